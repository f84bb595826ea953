"""Network models (layer 5): one module per network.

Each module holds a frozen dataclass config (defaults = the paper's sizes or our documented reconstruction),
``init_params(config, rng, dtype)`` returning a flat dict with PyTorch state-dict names, a sequence
forward/backward pair and a ``step`` for online use (the function the ONNX exporter translates).

Modules: ``refimpl.models.qtg`` (Quaternion Transition Generator, Geleijn et al. 2021; spec/qtg.md) with its fast
paths ``refimpl.models.qtg_fast`` (training) and ``refimpl.models.qtg_fast_inference`` (spec/architecture.md §Fast
paths); ``refimpl.models.quaternet`` (QuaterNet recurrent pose network, short- and long-term; spec/quaternet.md
§1-§4) with its training sequence ``refimpl.models.quaternet_sequence`` and the long-term network over current dual
quaternions ``refimpl.models.quaternet_long_dq`` (spec/locomotion.md §11); ``refimpl.models.quaternet_cnn``
(QuaterNet convolutional pose network, our reconstruction; spec/quaternet.md §5); ``refimpl.models.pace`` (the
pace network of the long-term model; spec/locomotion.md); ``refimpl.models.acrnn`` (acRNN with the
dual-quaternion paper's representations; spec/acrnn.md); ``refimpl.models._shared`` (helpers the modules share).
Import from the submodules; this package re-exports nothing, so the model modules stay independent.
"""
