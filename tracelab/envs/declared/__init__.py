"""Worlds declared by a spec beside a rule program (docs/worlds.md): the spec file and its expressions
(spec_file, expressions), the board (board), the checked spec (spec), the running world (world), the
gymnasium Env (gym_env) and the toy-text games' registrations (toytext)."""
