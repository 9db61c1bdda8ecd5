"""The walker's MuJoCo Warp model (``backend="warp"``): the options :class:`~jaxterrain.walker.env.WalkerEnv` sets on
MJX's Warp model after ``mjx.put_model(impl="warp")``."""

from __future__ import annotations

__all__ = ["SOLVER_CAP_WARNINGS", "quiet_solver_caps"]

SOLVER_CAP_WARNINGS = ("ITERATIONS", "LS_ITERATIONS")
"""MuJoCo Warp's overflow warnings switched off on the walker's model: a world that ends its step at the solver's
(or line search's) iteration cap. The walker caps Newton's iterations by design (:class:`SolverOptions`), so under
load most worlds reach the cap every step, and each printed one line from the GPU: 5.9 GB of log in 8 minutes for a
60-trial population and 5.3 GB for one treatment beside it (2 x H200, 2026-11-30). The cap is still recorded in
the Warp data's overflow flags; the warnings of overflowing buffers (contacts, CCD, heightfield) stay on."""


def quiet_solver_caps(mjx_model):
    """``mjx_model`` (``impl="warp"``) with :data:`SOLVER_CAP_WARNINGS` cleared from ``opt.warn_overflow`` (a
    static field: read when Warp's kernels are built). A model of another MJX version without it is returned as
    is."""
    impl = getattr(mjx_model.opt, "_impl", None)
    if impl is None or not hasattr(impl, "warn_overflow"):
        return mjx_model
    from mujoco.mjx.third_party.mujoco_warp import OverflowType

    off = 0
    for name in SOLVER_CAP_WARNINGS:
        off |= int(getattr(OverflowType, name, 0))
    impl = impl.replace(warn_overflow=int(impl.warn_overflow) & ~off)
    return mjx_model.replace(opt=mjx_model.opt.replace(_impl=impl))
