"""refimpl: reference NumPy implementation of QuaterNet, the dual-quaternion pose representation and QTG.

Manual backprop, no autograd; NumPy is the only dependency. See ``spec/architecture.md`` for the layering and
``spec/conventions.md`` for the conventions (quaternions ``(w, x, y, z)``, Hamilton product, active rotations,
right-handed frames, dual quaternions ``(q_r | q_d)`` with ``q_d = ½ (0, t) ⊗ q_r``).

The top level re-exports layers 1-3 and 6 (math, kinematics, data, optimisation and checkpoints) by name.
Layers, losses and models keep their namespaces, because their names are only meaningful there:
``refimpl.nn`` (layers), ``refimpl.losses``, ``refimpl.models.qtg``, ``refimpl.representations``,
``refimpl.protocols`` (each paper's data, protocol, metrics and baselines), ``refimpl.train``.
"""
import importlib

from .quat import *  # noqa: F401,F403
from .rotations import *  # noqa: F401,F403
from .dualquat import *  # noqa: F401,F403
from .skeleton import *  # noqa: F401,F403
from .current_dq import *  # noqa: F401,F403
from .mirroring import *  # noqa: F401,F403
from .motion import *  # noqa: F401,F403
from .bvh import *  # noqa: F401,F403
from .bvh_write import *  # noqa: F401,F403
from .expmap import *  # noqa: F401,F403
from .skeletons import *  # noqa: F401,F403
from .preprocess import *  # noqa: F401,F403
from .optim import *  # noqa: F401,F403
from .schedules import *  # noqa: F401,F403
from .checkpoint import *  # noqa: F401,F403

from . import nn, losses, models, representations  # noqa: F401  (namespaces)

__version__ = "0.1.0"

__all__ = [name for mod in ("quat", "rotations", "dualquat", "skeleton", "current_dq", "mirroring", "motion", "bvh",
                            "bvh_write", "expmap", "skeletons", "preprocess", "optim", "schedules", "checkpoint")
           for name in importlib.import_module(f"{__name__}.{mod}").__all__]
__all__ += ["nn", "losses", "models", "representations", "__version__"]
