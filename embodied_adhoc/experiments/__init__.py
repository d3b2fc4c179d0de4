"""The episode loop, the trial runner with its domain plug-ins and execution backends, statistics (bootstrap
intervals, IQM, probability of improvement, Welch tests), tables and plots (docs/trials.md).

Where this layer sits and what it may import: docs/layout.md."""
