"""Synthesis protocol of the dual-quaternion paper (acRNN on salsa): its metrics (Table 1, spec/acrnn.md §6).

:func:`root_zeroed_positions`, :func:`mean_joint_error` (Euclidean, root zeroed), :func:`npss` (Gopalakrishnan
et al.'s power spectrum ``|X|²`` = ``"power"``, or the LaFAN1 ``fast_npss`` copy used by the dual-quaternion
paper's evaluation, ``(Re X)²`` = ``"real"``) and :func:`mean_acceleration` / :func:`acceleration_comparison`.

Shape legend: N sequences, T frames, J joints, D features.
"""
from __future__ import annotations

import numpy as np

from refimpl.nn.params import check_float_array
from refimpl.representations import REPRESENTATIONS, decode, positions_from_frames
from refimpl.skeleton import Skeleton

__all__ = ["NPSS_VARIANTS", "root_zeroed_positions", "mean_joint_error", "npss", "mean_acceleration",
           "acceleration_comparison"]


# --------------------------------------------------------------------------------------------------
# synthesis metrics (dual-quaternion paper, Table 1; spec/acrnn.md §6)

#: ``"power"``: Gopalakrishnan et al. (CVPR 2019), ``P = |X|²``; ``"real"``: LaFAN1 ``fast_npss`` as copied into
#: the dual-quaternion paper's evaluation code, ``P = (Re X)²``.
NPSS_VARIANTS = ("power", "real")


def root_zeroed_positions(representation: str, skeleton: Skeleton, frames, source: str = "fk") -> np.ndarray:
    """Joint positions implied by frame vectors with the root position set to 0 (the paper ignores the root).

    Parameters
    ----------
    representation : str
    skeleton : Skeleton with J joints
    frames : ndarray (..., 3 + D·J)
        De-standardised frames.
    source : {"fk", "stored"}
        ``"fk"`` (default; the paper: "computed using Forward Kinematics", and the DQ evaluation code decodes
        current DQs to local rotations first): forward kinematics of the decoded local rotations with the
        skeleton's offsets, for every representation with an inverse; ``"positions"`` has none and uses its stored
        positions. ``"stored"``: :func:`refimpl.representations.positions_from_frames` (stored positions of the
        ``+positions`` representations, Eq. 8 translations of dual quaternions).

    Returns
    -------
    ndarray (..., J, 3)
    """
    if source not in ("fk", "stored"):
        raise ValueError(f"source: expected 'fk' or 'stored', got {source!r}")
    x = np.array(frames, dtype=np.float64)
    x[..., :3] = 0.0
    rep = REPRESENTATIONS.get(representation)
    if source == "fk" and rep is not None and rep.invertible:
        rot, root = decode(representation, skeleton, x)
        return skeleton.forward_kinematics(rot, root)
    return positions_from_frames(representation, skeleton, x)


def mean_joint_error(pred, gt) -> float:
    """Euclidean joint-position error: ``mean over (..., J) of ‖p − p̃‖₂``.

    Parameters
    ----------
    pred, gt : ndarray (..., J, 3)
        Positions (root zeroed, :func:`root_zeroed_positions`).
    """
    pred = check_float_array(pred, "pred", (..., 3))
    gt = check_float_array(gt, "gt", pred.shape)
    return float(np.mean(np.sqrt(np.sum((pred - gt) ** 2, axis=-1))))


def _flat_sequences(x, name, shape=None):
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 3 or (shape is not None and a.shape != shape):
        raise ValueError(f"{name}: expected shape (N, T, D...) {'' if shape is None else shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a.reshape(a.shape[0], a.shape[1], -1)


def npss(gt, pred, variant: str = "power") -> float:
    """Normalized Power Spectrum Similarity (Gopalakrishnan et al., CVPR 2019).

    Per sequence s and feature d, along time (FFT over the T frames, ``k = 0 … T−1``)::

        P[s,k,d] = |X[s,k,d]|²   ("power", the original)   or   (Re X[s,k,d])²   ("real", LaFAN1 fast_npss)
        p̂ = P / Σ_k P            (0 where the total is 0)
        EMD[s,d] = Σ_k | cumsum_k p̂_pred − cumsum_k p̂_gt |
        NPSS = Σ_{s,d} W[s,d] EMD[s,d] / Σ_{s,d} W[s,d],   W = Σ_k P_gt   (ground-truth total power)

    Parameters
    ----------
    gt, pred : ndarray (N, T, ...)
        Sequences; trailing axes are flattened into features (e.g. (N, T, J, 3) positions).
    variant : {"power", "real"}

    Returns
    -------
    float
        0 for identical sequences. ``"power"`` is invariant to a common circular time shift of both (and to a
        circular shift of either); ``"real"`` is not.
    """
    if variant not in NPSS_VARIANTS:
        raise ValueError(f"variant: expected one of {NPSS_VARIANTS}, got {variant!r}")
    g = _flat_sequences(gt, "gt")
    p = _flat_sequences(pred, "pred", np.shape(gt))
    X_g, X_p = np.fft.fft(g, axis=1), np.fft.fft(p, axis=1)                 # (N, T, D) complex
    if variant == "power":
        P_g, P_p = np.abs(X_g) ** 2, np.abs(X_p) ** 2
    else:
        P_g, P_p = X_g.real ** 2, X_p.real ** 2
    W_g, W_p = P_g.sum(axis=1), P_p.sum(axis=1)                              # (N, D)
    if not np.any(W_g > 0):
        raise ValueError("gt: every feature has zero power (NPSS is undefined)")
    n_g = np.divide(P_g, W_g[:, None], out=np.zeros_like(P_g), where=W_g[:, None] > 0)
    n_p = np.divide(P_p, W_p[:, None], out=np.zeros_like(P_p), where=W_p[:, None] > 0)
    emd = np.sum(np.abs(np.cumsum(n_p, axis=1) - np.cumsum(n_g, axis=1)), axis=1)   # (N, D)
    return float(np.sum(W_g * emd) / np.sum(W_g))


def mean_acceleration(positions) -> float:
    """Mean acceleration magnitude (VIBE-style, the paper's jitter measure), in position units per frame².

    ``a_t = p_{t+2} − 2 p_{t+1} + p_t``; ``‖a_t,j‖₂`` averaged over joints, frames and sequences.

    Parameters
    ----------
    positions : ndarray (N, T, J, 3), T >= 3
    """
    x = check_float_array(positions, "positions", (None, None, None, 3))
    if x.shape[1] < 3:
        raise ValueError(f"positions: expected at least 3 frames, got shape {x.shape}")
    a = x[:, 2:] - 2.0 * x[:, 1:-1] + x[:, :-2]                            # (N, T-2, J, 3)
    return float(np.mean(np.sqrt(np.sum(a * a, axis=-1))))


def acceleration_comparison(pred, gt) -> dict:
    """Mean acceleration of the prediction and of the data, and their absolute difference.

    Returns
    -------
    dict with ``"pred"``, ``"gt"``, ``"abs_diff"`` (the paper's Table 1 column is one of these; it does not say
    which, spec/acrnn.md §6).
    """
    a_p, a_g = mean_acceleration(pred), mean_acceleration(gt)
    return {"pred": a_p, "gt": a_g, "abs_diff": abs(a_p - a_g)}
