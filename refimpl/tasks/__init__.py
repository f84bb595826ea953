"""Task pipelines (data sets and recipes built on the models): refimpl.tasks.locomotion, ..."""
