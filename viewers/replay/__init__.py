"""`tracelab replay`: traced games as rerun recordings, with the rules that fired annotated (docs/replay.md)."""
