"""Training: DQN against the scripted opponent, evaluation, and experiments (docs/training.md)."""
