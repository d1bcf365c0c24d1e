"""The game: scenarios, the map as facts, the scripted opponent, and its two simulators (RefSim,
hand-written; RuleSim, driven by rules/gridworld/game.rules), which share state.py and observe.py."""
