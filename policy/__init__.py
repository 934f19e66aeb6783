"""Image policies: the CNN, behaviour cloning, finetuning, augmentation, evaluation, checkpoints."""

from policy.augment import augment
from policy.base import base_policy
from policy.checkpoint import load_policy, save_policy
from policy.evaluate import evaluate, failing_test_task
from policy.model import ImagePolicy, Policy, PolicyConfig
from policy.train import TrainConfig, behaviour_clone, finetune, training_demos

__all__ = [
    "ImagePolicy",
    "Policy",
    "PolicyConfig",
    "TrainConfig",
    "augment",
    "base_policy",
    "behaviour_clone",
    "evaluate",
    "failing_test_task",
    "finetune",
    "load_policy",
    "save_policy",
    "training_demos",
]
