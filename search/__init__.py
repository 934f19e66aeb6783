"""Counterfactual search over concept edits. Pure: results go out through callbacks only."""

from search.counterfactual import SearchConfig, SearchResult, counterfactual_search
from search.enumerate import combinations, count, singles
from search.lockstep import Candidate, compared_steps, distance_to_demo, rollout_lockstep

__all__ = [
    "Candidate",
    "SearchConfig",
    "SearchResult",
    "combinations",
    "compared_steps",
    "count",
    "counterfactual_search",
    "distance_to_demo",
    "rollout_lockstep",
    "singles",
]
