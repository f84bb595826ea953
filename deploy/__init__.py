"""deploy: ONNX export of the refimpl networks and a small onnxruntime wrapper.

Built with the onnx package's own graph API (no PyTorch, no tracing). One builder module per layer family
(``linear``, ``activations``, ``gru``, ``lstm``, ``conv1d``, ``quat``, ``kinematics``, ``features``), block
quantisation for onnxruntime's ``MatMulNBits`` (``quantize``), the per-model exporters and runtimes with the
exporter table (``deploy.models``: one graph module and one entry module ``*_io`` per model; QTG's ``qtg``,
``qtg_compact``, ``qtg_io`` are re-exported here), validation (``validate``: checker,
strict shape inference, the ONNX reference evaluator, onnxruntime), sessions (``session``) and the generic
runtime wrapper (``runtime``), the portable export target (``portable``). See ``spec/deploy.md`` and
``deploy/README.md`` (input/output contract, C API example).

Requires the ``deploy`` extra: ``pip install 'refimpl[deploy]'``.
"""
import importlib

from .graph import *  # noqa: F401,F403
from .linear import *  # noqa: F401,F403
from .activations import *  # noqa: F401,F403
from .recurrent import *  # noqa: F401,F403
from .gru import *  # noqa: F401,F403
from .lstm import *  # noqa: F401,F403
from .conv1d import *  # noqa: F401,F403
from .quat import *  # noqa: F401,F403
from .kinematics import *  # noqa: F401,F403
from .features import *  # noqa: F401,F403
from .metadata import *  # noqa: F401,F403
from .quantize import *  # noqa: F401,F403
from .validate import *  # noqa: F401,F403
from .session import *  # noqa: F401,F403
from .runtime import *  # noqa: F401,F403
from .portable import *  # noqa: F401,F403
from .models.qtg import *  # noqa: F401,F403
from .models.qtg_compact import *  # noqa: F401,F403
from .models.qtg_io import *  # noqa: F401,F403

# (the functions deploy.linear, deploy.gru, deploy.lstm shadow their modules here, so the modules are looked up)
__all__ = [n for m in ("graph", "linear", "activations", "recurrent", "gru", "lstm", "conv1d", "quat", "kinematics",
                       "features", "metadata", "quantize", "validate", "session", "runtime", "portable", "models.qtg",
                       "models.qtg_compact", "models.qtg_io")
           for n in importlib.import_module(f"{__name__}.{m}").__all__]
