"""Conditions compared with one participant's answers kept together (`dfa study analyse`).

A participant answers every question of their plan, and in a `within` design under every
condition, so the answers are not independent draws: the chi-squared of analysis.py pools
them as if they were. Two analyses that do not:

    mixed       a mixed-effects logistic model, correct ~ condition with random intercepts per
                participant and per task (statsmodels' BinomialBayesMixedGLM, fitted by
                variational Bayes; its priors: N(0, 2^2) on the fixed effects, the default
                on the random effects' log standard deviations). Per condition against the
                baseline: the posterior mean of the log-odds difference, its 95% interval
                (mean +- 1.96 posterior sd) and the posterior probability that it is > 0.
                Variational Bayes understates posterior spread; the interval is a guide.
    stratified  an exact conditional test with the tasks as strata: within a task that both
                conditions saw, the count of right answers under the condition is
                hypergeometric given the task's margins if the condition makes no difference;
                the sum over tasks has the convolution of those laws, and the two-sided p sums
                the probabilities no larger than the observed one's. Exact at any size, and
                what to read when the model cannot be fitted.
"""

from __future__ import annotations

import math
import warnings
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

Z95 = 1.959963984540054


@dataclass(frozen=True)
class Effect:
    """One condition against the baseline in the mixed model (log-odds of a right answer)."""

    condition: str
    baseline: str
    mean: float
    """Posterior mean of the log-odds difference."""
    sd: float
    """Posterior standard deviation."""

    @property
    def low(self) -> float:
        return self.mean - Z95 * self.sd

    @property
    def high(self) -> float:
        return self.mean + Z95 * self.sd

    @property
    def p_positive(self) -> float:
        """Posterior probability that the condition raises the odds of a right answer."""
        return 0.5 * (1 + math.erf(self.mean / (self.sd * math.sqrt(2))))


@dataclass(frozen=True)
class MixedFit:
    """The mixed model's effects, or why there are none (`note`)."""

    effects: tuple[Effect, ...]
    answers: int
    participants: int
    tasks: int
    participant_sd: float = math.nan
    task_sd: float = math.nan
    note: str = ""


def mixed_model(rows: list[dict], conditions: tuple[str, ...]) -> MixedFit:
    """Fit correct ~ condition + (1 | participant) + (1 | task) over `rows` (answers.csv's)."""
    import pandas as pd
    from statsmodels.genmod.bayes_mixed_glm import BinomialBayesMixedGLM

    base = "none" if "none" in conditions else conditions[0]
    present = [c for c in conditions if any(r["condition"] == c for r in rows)]
    people = len({r["participant"] for r in rows})
    tasks = len({r["task"] for r in rows})
    empty = MixedFit((), len(rows), people, tasks)
    if base not in present or len(present) < 2:
        return _note(empty, f"needs answers under {base} and another condition")
    if people < 2 or tasks < 2:
        return _note(empty, "needs at least two participants and two tasks")
    order = [base, *(c for c in present if c != base)]
    df = pd.DataFrame(
        {
            "correct": [int(r["correct"]) for r in rows],
            "condition": pd.Categorical([r["condition"] for r in rows], categories=order),
            "participant": [str(r["participant"]) for r in rows],
            "task": [str(r["task"]) for r in rows],
        }
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a fit that does not converge is no fit
            model = BinomialBayesMixedGLM.from_formula(
                "correct ~ condition",
                {"participant": "0 + C(participant)", "task": "0 + C(task)"},
                df,
            )
            fit = model.fit_vb()
    except Exception as e:  # statsmodels raises many kinds; each means no usable fit
        return _note(empty, f"the model could not be fitted ({type(e).__name__}: {e})")
    mean, sd = np.asarray(fit.fe_mean), np.asarray(fit.fe_sd)
    if not (np.isfinite(mean).all() and np.isfinite(sd).all() and (sd > 0).all()):
        return _note(empty, "the model's fit is not finite")
    vc = dict(zip(model.vcp_names, np.exp(np.asarray(fit.vcp_mean)), strict=True))
    effects = tuple(
        Effect(c, base, float(mean[i]), float(sd[i])) for i, c in enumerate(order[1:], start=1)
    )
    return MixedFit(effects, len(rows), people, tasks, vc["participant"], vc["task"])


def _note(fit: MixedFit, why: str) -> MixedFit:
    return MixedFit((), fit.answers, fit.participants, fit.tasks, note=why)


@dataclass(frozen=True)
class Stratified:
    """The exact conditional test of one condition against the baseline, tasks as strata."""

    condition: str
    baseline: str
    strata: int
    """Tasks answered under both conditions (the others say nothing here)."""
    right: int
    """Right answers under the condition in those tasks."""
    expected: float
    """Their expected number if the condition made no difference."""
    p: float
    """Two-sided exact p (NaN without a stratum)."""


def stratified_exact(rows: list[dict], conditions: tuple[str, ...]) -> list[Stratified]:
    """Each condition against the baseline, tasks as strata (see the module's docstring)."""
    from scipy.stats import hypergeom

    base = "none" if "none" in conditions else conditions[0]
    out = []
    for c in conditions:
        if c == base:
            continue
        cells: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0, 0])  # right/n: c, base
        for r in rows:
            if r["condition"] in (c, base):
                k = 0 if r["condition"] == c else 2
                cells[r["task"]][k] += int(r["correct"])
                cells[r["task"]][k + 1] += 1
        law = np.ones(1)
        right, expected, strata = 0, 0.0, 0
        for a, n_c, b, n_b in cells.values():
            if not n_c or not n_b:
                continue
            strata += 1
            right += a
            total, hits = n_c + n_b, a + b
            support = np.arange(max(0, hits - n_b), min(hits, n_c) + 1)
            pmf = np.zeros(min(hits, n_c) + 1)
            pmf[support] = hypergeom(total, hits, n_c).pmf(support)
            expected += n_c * hits / total
            law = np.convolve(law, pmf)
        if not strata:
            out.append(Stratified(c, base, 0, 0, 0.0, math.nan))
            continue
        p = float(law[law <= law[right] * (1 + 1e-7)].sum())
        out.append(Stratified(c, base, strata, right, expected, min(1.0, p)))
    return out


def markdown(fit: MixedFit, exact: list[Stratified], design: str) -> list[str]:
    """The section of accuracy.md with both analyses."""
    why = (
        "In this within-subject design every participant answers under every condition, so "
        "the χ² above, which takes each answer as independent, is not the test to read: "
        "these are."
        if design == "within"
        else "Each participant gives several answers, which the χ² above takes as "
        "independent (as the paper's analysis did); these two keep a participant's answers "
        "together."
    )
    lines = [
        "",
        "## Conditions compared, one participant's answers kept together",
        "",
        why,
        "",
        "Mixed-effects logistic model, right ~ condition + (1 | participant) + (1 | task) "
        "(statsmodels BinomialBayesMixedGLM, variational Bayes; fixed-effect prior "
        f"N(0, 2²)); {fit.answers} answers, {fit.participants} participants, {fit.tasks} "
        "tasks.",
        "",
    ]
    if fit.effects:
        lines += [
            "| condition | against | log-odds difference | 95% interval | odds ratio "
            "| P(difference > 0) |",
            "|---|---|---|---|---|---|",
            *(
                f"| {e.condition} | {e.baseline} | {e.mean:+.2f} | {e.low:+.2f} to "
                f"{e.high:+.2f} | {math.exp(e.mean):.3g} | {e.p_positive:.3f} |"
                for e in fit.effects
            ),
            "",
            f"Random intercepts' standard deviations: participants {fit.participant_sd:.2f}, "
            f"tasks {fit.task_sd:.2f} (log-odds).",
        ]
    else:
        lines.append(f"Not fitted: {fit.note}. Read the exact test below.")
    lines += [
        "",
        "Exact conditional test, tasks as strata (two-sided):",
        "",
        "| condition | against | tasks with both | right under it | expected | exact p |",
        "|---|---|---|---|---|---|",
        *(
            f"| {s.condition} | {s.baseline} | {s.strata} | {s.right} | {s.expected:.1f} | "
            + ("–" if math.isnan(s.p) else f"{s.p:.3g}")
            + " |"
            for s in exact
        ),
    ]
    return lines
