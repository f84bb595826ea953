"""Differentiable pieces (layer 4): layers as pure forward/backward pairs with explicit caches.

Calling convention (spec/architecture.md, spec/layers.md)::

    y, cache = name_forward(x, params, prefix, ...)     # layers with parameters (PyTorch names under prefix)
    dx, grads = name_backward(dy, cache)                # grads: full parameter name -> array
    y, cache = name_forward(x, ...)                     # parameter-free layers
    dx = name_backward(dy, cache)
    y, h_n, cache = gru_forward(x, h0, params, prefix, num_layers=1, bidirectional=False)
    dx, dh0, grads = gru_backward(dy, dh_n, cache)

Modules: :mod:`~refimpl.nn.params` (names, merging, initialisers, checks), :mod:`~refimpl.nn.linear`,
:mod:`~refimpl.nn.activations`, :mod:`~refimpl.nn.mlp` (dense chains; import the module, not re-exported),
:mod:`~refimpl.nn.gru`, :mod:`~refimpl.nn.lstm`, :mod:`~refimpl.nn.conv1d`,
:mod:`~refimpl.nn.quat_layers` (quaternion / dual-quaternion layers), :mod:`~refimpl.nn.kinematics_layers`
(forward kinematics and dual-quaternion skeleton layers); :mod:`~refimpl.nn.gru_fast` (kernels of QTG's reverse
step; kernel tier, not re-exported); :mod:`~refimpl.nn.gru_naive`, :mod:`~refimpl.nn.lstm_naive` (the slow
per-gate oracles of the two recurrent layers; not re-exported).
"""
from refimpl.nn import activations, conv1d, gru, kinematics_layers, linear, lstm, params, quat_layers
from refimpl.nn.activations import *  # noqa: F401,F403
from refimpl.nn.conv1d import *  # noqa: F401,F403
from refimpl.nn.gru import *  # noqa: F401,F403
from refimpl.nn.kinematics_layers import *  # noqa: F401,F403
from refimpl.nn.linear import *  # noqa: F401,F403
from refimpl.nn.lstm import *  # noqa: F401,F403
from refimpl.nn.params import *  # noqa: F401,F403
from refimpl.nn.quat_layers import *  # noqa: F401,F403

__all__ = (params.__all__ + linear.__all__ + activations.__all__ + gru.__all__ + lstm.__all__ + conv1d.__all__
           + quat_layers.__all__ + kinematics_layers.__all__)
