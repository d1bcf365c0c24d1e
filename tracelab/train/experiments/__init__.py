"""The method's experiments as commands with reports (docs/experiments/): definitions (what each trains), runner (one seed: train, final evaluations), run (an experiment), report and plots."""
