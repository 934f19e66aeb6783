"""Feature statistics as LeRobot computes them (`datasets/compute_stats.py` of LeRobot 0.6.1).

Per episode and feature: min, max, mean, std, count and the quantiles q01, q10, q50, q90, q99,
estimated from a 5,000-bin histogram of the episode's values (interpolated within a bin), over
each dimension of a vector feature, or each channel of an image feature (evenly spread frames:
all of a short episode, 100, or n ** 0.75 of n; channel-first, in [0, 1]: stats of shape
(3, 1, 1)). Inputs are
promoted to at least float32 before squares are taken. An episode's stats go into its row of
meta/episodes (stats/<feature>/<stat>); meta/stats.json aggregates them episode by episode:
min of mins, max of maxes, count-weighted mean, the pooled variance, count-weighted quantiles.
String features have none.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
BINS = 5000
Stats = dict[str, np.ndarray]


def sample_indices(n: int) -> list[int]:
    """The frames an image's stats are taken from: evenly spread, at least 100 (or all),
    n ** 0.75 of them, at most 10,000."""
    least = min(n, 100)
    k = max(least, min(int(n**0.75), 10_000))
    return np.round(np.linspace(0, n - 1, k)).astype(int).tolist()


def _quantile(hist: np.ndarray, edges: np.ndarray, target: float) -> float:
    cumsum = np.cumsum(hist)
    i = int(np.searchsorted(cumsum, target))
    if i == 0:
        return float(edges[0])
    if i >= len(cumsum):
        return float(edges[-1])
    before = cumsum[i - 1]
    inside = cumsum[i] - before
    if inside == 0:
        return float(edges[i])
    return float(edges[i] + (target - before) / inside * (edges[i + 1] - edges[i]))


def vector_stats(batch: np.ndarray, count: int) -> Stats:
    """Stats of (N, D) values per dimension; `count` is the number of samples they stand for."""
    # at least float32 before squares are taken (LeRobot); here also on the short path, where
    # LeRobot keeps the stored type, so that every episode's stats are numbers of one kind
    batch = batch.astype(np.result_type(batch.dtype, np.float32), copy=False)
    if batch.shape[0] < 2:  # too few for quantiles: the mean stands for them
        out = {
            "min": np.min(batch, axis=0),
            "max": np.max(batch, axis=0),
            "mean": np.mean(batch, axis=0),
            "std": np.std(batch, axis=0),
            "count": np.array([count]),
        }
        return out | {q: out["mean"].copy() for q in QUANTILE_KEYS}
    lo, hi = np.min(batch, axis=0), np.max(batch, axis=0)
    mean = np.mean(batch, axis=0)
    squares = np.mean(batch**2, axis=0)
    out = {
        "min": lo.copy(),
        "max": hi.copy(),
        "mean": mean.copy(),
        "std": np.sqrt(np.maximum(0, squares - mean**2)),
        "count": np.array([count]),
    }
    n = batch.shape[0]
    per_dim = []
    for d in range(batch.shape[1]):
        edges = np.linspace(lo[d] - 1e-10, hi[d] + 1e-10, BINS + 1)
        hist = np.histogram(batch[:, d], bins=edges)[0].astype(np.float64)
        per_dim.append((hist, edges))
    for q, key in zip(QUANTILES, QUANTILE_KEYS, strict=True):
        out[key] = np.array([_quantile(h, e, q * n) for h, e in per_dim])
    return out


def feature_stats(values: np.ndarray, dtype: str) -> Stats:
    """One episode's stats of one feature: values (T,) or (T, D) for numbers, uint8
    (T, H, W, 3) frames for an image or video feature."""
    if dtype in ("image", "video"):
        frames = values[sample_indices(len(values))].transpose(0, 3, 1, 2)  # (K, 3, H, W)
        h, w = frames.shape[2:]
        if max(h, w) >= 300:  # LeRobot's auto_downsample_height_width
            step = int(w / 150) if w > h else int(h / 150)
            frames = frames[:, :, ::step, ::step]
        pixels = frames.transpose(0, 2, 3, 1).reshape(-1, frames.shape[1])  # (K*H*W, 3)
        s = vector_stats(pixels, len(frames))
        return {k: v if k == "count" else (v / 255.0).reshape(-1, 1, 1) for k, v in s.items()}
    if values.ndim == 1:  # a plain column: stats of shape (1,)
        return {
            k: v.reshape(1) for k, v in vector_stats(values.reshape(-1, 1), len(values)).items()
        }
    return vector_stats(values, len(values))


def episode_stats(columns: Mapping[str, Any], features: Mapping[str, Mapping[str, Any]]) -> dict:
    """Every non-string feature's stats for one episode, in the features' order."""
    return {
        key: feature_stats(np.asarray(columns[key]), f["dtype"])
        for key, f in features.items()
        if f["dtype"] != "string"
    }


def _aggregate_feature(stats: Sequence[Stats]) -> Stats:
    means = np.stack([s["mean"] for s in stats])
    variances = np.stack([s["std"] ** 2 for s in stats])
    counts = np.stack([s["count"] for s in stats])
    total = counts.sum(axis=0)
    while counts.ndim < means.ndim:
        counts = np.expand_dims(counts, axis=-1)
    mean = (means * counts).sum(axis=0) / total
    variance = ((variances + (means - mean) ** 2) * counts).sum(axis=0) / total
    out = {
        "min": np.min(np.stack([s["min"] for s in stats]), axis=0),
        "max": np.max(np.stack([s["max"] for s in stats]), axis=0),
        "mean": mean,
        "std": np.sqrt(variance),
        "count": total,
    }
    for key in QUANTILE_KEYS:
        if all(key in s for s in stats):
            out[key] = (np.stack([s[key] for s in stats]) * counts).sum(axis=0) / total
    return out


def aggregate(stats: Sequence[dict]) -> dict:
    """The dataset's stats from its episodes', folded in one episode at a time as LeRobot's
    writer does (each new episode aggregated with the running total)."""
    total: dict | None = None
    for episode in stats:
        if total is None:
            total = episode
            continue
        keys = list(dict.fromkeys([*total, *episode]))
        total = {k: _aggregate_feature([s[k] for s in (total, episode) if k in s]) for k in keys}
    return total or {}


def to_json(stats: Mapping[str, Stats]) -> dict:
    """Plain lists and numbers, as LeRobot's serialize_dict writes meta/stats.json."""
    return {k: {s: np.asarray(v).tolist() for s, v in f.items()} for k, f in stats.items()}


def flat(stats: Mapping[str, Stats]) -> dict[str, list]:
    """An episode's stats as its meta/episodes columns: stats/<feature>/<stat> -> list."""
    return {
        f"stats/{k}/{s}": np.asarray(v).tolist() for k, f in stats.items() for s, v in f.items()
    }
