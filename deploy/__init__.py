"""deploy: ONNX export of the refimpl networks and a small onnxruntime wrapper.

Built with the onnx package's own graph API (no PyTorch, no tracing). One builder module per layer family
(``linear``, ``activations``, ``gru``, ``lstm``, ``conv1d``, ``quat``, ``kinematics``, ``features``), block
quantisation for onnxruntime's ``MatMulNBits`` (``quantize``), the per-model exporters and runtimes with the
exporter table (``deploy.models``: ``qtg``, ``qtg_compact``, ``qtg_io``), validation (``validate``: checker,
strict shape inference, the ONNX reference evaluator, onnxruntime), sessions (``session``) and the generic
runtime wrapper (``runtime``). See ``spec/deploy.md`` and
``deploy/README.md`` (input/output contract, C API example).

Requires the ``deploy`` extra: ``pip install 'refimpl[deploy]'``.
"""
from . import (graph as _graph, linear as _linear, activations as _activations, recurrent as _recurrent,
               gru as _gru, lstm as _lstm, conv1d as _conv1d, quat as _quat, kinematics as _kinematics,
               features as _features, metadata as _metadata, quantize as _quantize, validate as _validate,
               session as _session, runtime as _runtime)
from .models import qtg as _qtg, qtg_compact as _qtg_compact, qtg_io as _qtg_io
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
from .models.qtg import *  # noqa: F401,F403
from .models.qtg_compact import *  # noqa: F401,F403
from .models.qtg_io import *  # noqa: F401,F403

__all__ = [n for m in (_graph, _linear, _activations, _recurrent, _gru, _lstm, _conv1d, _quat, _kinematics,
                       _features, _metadata, _quantize, _validate, _session, _runtime, _qtg, _qtg_compact, _qtg_io)
           for n in m.__all__]
