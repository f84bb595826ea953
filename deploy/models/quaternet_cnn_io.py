"""The convolutional QuaterNet's entry of the exporter table (``deploy.models.EXPORTERS["quaternet-cnn"]``): the
table's names bound to the CNN functions of ``deploy/models/quaternet_io.py``."""
from __future__ import annotations

from deploy.models.quaternet_io import QuaterNetCNNRuntime, export_cnn_dir, load_cnn_checkpoint

__all__ = ["load_checkpoint", "export_dir", "Runtime"]

load_checkpoint = load_cnn_checkpoint
export_dir = export_cnn_dir
Runtime = QuaterNetCNNRuntime

# ``python -m deploy``'s commands for this model (deploy/cli.py calls them through the exporter table)
from deploy.models.quaternet_io import add_run_options, run_command  # noqa: E402,F401
