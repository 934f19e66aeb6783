"""The experiments: the paper's finetuning comparison (Q2: four conditions, budgets, seeds, any
backend) and the explanation benchmark.

conditions.py  the four conditions, who picks which concept, the paper's accuracies and numbers
runner.py      one run: (world, shift, condition, budget, seed) -> one row, from the loop's
               own steps (dfa_viz.loop)
results.py     the resumable results folder, statistics, the Markdown table
figures.py     PNG plots and the .rrd of the curves
experiment.py  planning, resuming, running, reporting (on dfa_viz.backends: a local process
               pool or a Ray cluster)
args.py        Q2Args and ExplainArgs (their options), the explanation benchmark's name tables
cli.py         `experiment_q2`, the `dfa experiment q2` subcommand; `experiment_explain`,
               `dfa experiment explain`

The explanation benchmark (`dfa experiment explain`): explain.py (one task: every explainer's
ranking of the concepts against the planted cause), explain_run.py (the plan and the run),
explain_results.py (the resumable folder, Wilson intervals, the Markdown table),
explain_figures.py (the bars).

Importing this package imports nothing heavy; torch comes with runner.py.
"""
