"""refimpl: reference NumPy implementation of QuaterNet, the dual-quaternion pose representation and QTG.

Manual backprop, no autograd; NumPy is the only dependency. The public API is re-exported here; see
``spec/architecture.md`` for the layering and ``spec/conventions.md`` for the conventions
(quaternions ``(w, x, y, z)``, Hamilton product, active rotations, right-handed frames, dual quaternions
``(q_r | q_d)`` with ``q_d = ½ (0, t) ⊗ q_r``).
"""
__version__ = "0.1.0"
