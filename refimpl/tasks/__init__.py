"""Tasks (layer 6): the data and evaluation of each benchmark, one module per task."""
