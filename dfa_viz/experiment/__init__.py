"""The paper's finetuning comparison (issue Q2): four conditions, budgets, seeds, any backend.

conditions.py  the four conditions, user concepts, the paper's accuracies and numbers
augmentation.py  variants of the demonstration over a concept; filling a budget
runner.py      one run: (world, shift, condition, budget, seed) -> one row
backends.py    a local process pool or a Ray cluster
results.py     the resumable results folder, statistics, the Markdown table
figures.py     PNG plots and the .rrd of the curves
experiment.py  planning, resuming, running, reporting
cli.py         `experiment_q2`, the `dfa experiment q2` subcommand

Importing this package imports nothing heavy; torch comes with runner.py.
"""
