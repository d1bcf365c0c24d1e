"""PyReason's hello world (its docs, "Hello World") with only the import changed: run it with
`python examples/pyreason_hello_world.py` (docs/pyreason.md, "Switching from PyReason")."""
from pathlib import Path

import tracelab.pyreason as pr

graph_path = Path(__file__).resolve().parent.parent / "tests" / "data" / "pyreason" / "friends_graph.graphml"

pr.settings.verbose = True
pr.settings.atom_trace = True

pr.load_graphml(graph_path)
pr.add_rule(pr.Rule('popular(x) <-1 popular(y), Friends(x,y), owns(y,z), owns(x,z)', 'popular_rule'))
pr.add_fact(pr.Fact('popular(Mary)', 'popular_fact', 0, 2))

interpretation = pr.reason(timesteps=2)

dataframes = pr.filter_and_sort_nodes(interpretation, ['popular'])
for t, df in enumerate(dataframes):
    print(f'TIMESTEP - {t}')
    print(df)
    print()
