"""Task protocols (data, splits, windows, evaluation) built on the models: one module per task."""
