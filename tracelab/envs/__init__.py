"""The environments over the simulators: gymnasium (gym_env), batched gymnasium (vector_env), PettingZoo
(parallel_env), their shared set-up (common), the per-episode tracer and the trace sinks."""
