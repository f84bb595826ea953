"""Consumers of the exported models written from their metadata and deploy/README.md alone: each imports only
NumPy, onnxruntime and the standard library (never ``refimpl`` or ``deploy``); ``tests/test_deploy_consumers.py``
checks the imports and compares every consumer with the NumPy model on real frames."""
