"""The paper's finetuning comparison (Q2): four conditions, budgets, seeds, any backend.

conditions.py  the four conditions, who picks which concept, the paper's accuracies and numbers
runner.py      one run: (world, shift, condition, budget, seed) -> one row, from the loop's
               own steps (dfa_viz.loop)
backends.py    a local process pool or a Ray cluster
results.py     the resumable results folder, statistics, the Markdown table
figures.py     PNG plots and the .rrd of the curves
experiment.py  planning, resuming, running, reporting
cli.py         Q2Args and `experiment_q2`, the `dfa experiment q2` subcommand

Importing this package imports nothing heavy; torch comes with runner.py.
"""
