"""Image policies: the CNN, behaviour cloning, finetuning, augmentation, evaluation, checkpoints,
and the loaders of policies from outside (register_policy_loader adds one)."""

from policy.base import base_policy
from policy.checkpoint import load_policy, save_policy
from policy.evaluate import Score, failing_test_task, score
from policy.loaders import register_policy_loader
from policy.model import ImagePolicy, Policy, PolicyConfig
from policy.train import TrainConfig, behaviour_clone, finetune, training_demos
from policy.variants import augment

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
    "save_policy",
    "score",
    "training_demos",
]
