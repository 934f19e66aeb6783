"""Image policies: the CNN, behaviour cloning, finetuning, augmentation, evaluation, checkpoints."""

from policy.base import base_policy
from policy.checkpoint import load_policy, save_policy
from policy.evaluate import Score, failing_test_task, score
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
    "save_policy",
    "score",
    "training_demos",
]
