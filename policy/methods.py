"""The saliency methods by name, written once: what `dfa run --saliency`, the page's saliency
layer, the explanation benchmark and the user study accept, and the name each is shown by.
Light to import: no torch (policy.saliency computes the maps).
"""

from __future__ import annotations

from sim.core import UserError

METHOD_NAMES = {
    "integrated_gradients": "Integrated Gradients",
    "occlusion": "Occlusion",
    "grad_cam": "Grad-CAM",
    "kernel_shap": "KernelSHAP (objects)",
}
"""Each method's name in titles, tables and plots, in the methods' order."""
METHODS = tuple(METHOD_NAMES)
"""The methods policy.saliency computes, in the order tables and plots list them."""


def check_method(method: str) -> str:
    """The method, or a UserError naming the accepted ones."""
    if method not in METHODS:
        raise UserError(f"unknown saliency method {method!r}; accepted: {', '.join(METHODS)}")
    return method
