"""The war game's hand-written oracle: scenarios, the scripted opponent and RefSim (with state.py and
observe.py), which the differential tests hold the spec (rules/gridworld/) equal to and `bench env`
measures against. The game itself runs only through its spec."""
