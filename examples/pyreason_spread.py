"""A spread over a random graph, written against PyReason's API: `python examples/pyreason_spread.py
GRAPH.graphml` (`tracelab bench pyreason` writes the graph: 2,000 nodes each linking to 5 random nodes,
`infected` on 10 of them, seeded; tracelab/bench/biggraph.py). With `import pyreason as pr` instead of the
first import it is a PyReason script; the bench runs it both ways (docs/pyreason.md, "Switching from
PyReason")."""
import sys

import tracelab.pyreason as pr

pr.settings.verbose = False
pr.load_graphml(sys.argv[1])
pr.add_rule(pr.Rule('infected(x) <-1 infected(y), link(y,x)', 'spread'))
interpretation = pr.reason(timesteps=10)  # t = 0..10: the 11 steps of docs/benchmarks/history.md's "Big graph"

last = pr.filter_and_sort_nodes(interpretation, ['infected'])[-1]
infected = sum(1 for bound in last['infected'] if bound[0] == 1)
print(f'infected at t = {interpretation.time}: {infected} nodes')
