"""The saliency methods' names, written once (policy.methods) and read without torch by the
command line, the explanation benchmark and the study."""

import subprocess
import sys

import pytest

from policy.methods import METHOD_NAMES, METHODS, check_method
from sim.core import UserError


def test_the_names_load_no_torch():
    code = (
        "import sys, policy.methods, dfa_viz.experiment.args, dfa_viz.cli; "
        "print(sorted(m for m in ('torch', 'captum') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_the_explainers_are_the_methods_between_the_search_and_the_floor():
    from dfa_viz.experiment.args import EXPLAINERS, ExplainArgs

    assert all(METHOD_NAMES[m] for m in METHODS)
    assert EXPLAINERS == ("counterfactual", *METHODS, "random") == ExplainArgs().methods


def test_an_unknown_method_is_one_line_naming_the_accepted_ones():
    assert check_method("grad_cam") == "grad_cam"
    with pytest.raises(UserError, match="accepted: " + ", ".join(METHODS)):
        check_method("lrp")
