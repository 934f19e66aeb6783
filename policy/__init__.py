"""Image policies: the CNN, behaviour cloning, finetuning, augmentation, evaluation, checkpoints,
and the loaders of policies from outside (register_policy_loader adds one).

Light to import: the names below are imported when first used, so that a module that needs no
torch (policy.methods, policy.variants) can be imported without it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from policy.base import base_policy
    from policy.checkpoint import load_policy, save_policy
    from policy.evaluate import Score, failing_test_task, score
    from policy.loaders import register_policy_loader
    from policy.model import ImagePolicy, Policy, PolicyConfig
    from policy.train import TrainConfig, behaviour_clone, finetune, replayed, training_demos
    from policy.variants import augment

_WHERE = {
    "base_policy": "policy.base",
    "load_policy": "policy.checkpoint",
    "save_policy": "policy.checkpoint",
    "Score": "policy.evaluate",
    "failing_test_task": "policy.evaluate",
    "score": "policy.evaluate",
    "register_policy_loader": "policy.loaders",
    "ImagePolicy": "policy.model",
    "Policy": "policy.model",
    "PolicyConfig": "policy.model",
    "TrainConfig": "policy.train",
    "behaviour_clone": "policy.train",
    "finetune": "policy.train",
    "replayed": "policy.train",
    "training_demos": "policy.train",
    "augment": "policy.variants",
}

__all__ = [
    "ImagePolicy",
    "Policy",
    "PolicyConfig",
    "Score",
    "TrainConfig",
    "augment",
    "base_policy",
    "behaviour_clone",
    "failing_test_task",
    "finetune",
    "load_policy",
    "register_policy_loader",
    "replayed",
    "save_policy",
    "score",
    "training_demos",
]


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'policy' has no attribute {name!r}")
