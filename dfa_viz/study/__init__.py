"""`dfa study`: the paper's user study run on the page, with and without explanations.

args       the options of `dfa study new|serve|analyse`
protocol   study.toml read and checked; each participant's balanced plan of questions
freeze     `dfa study new`: every task made once and frozen in the study folder
intro      the familiarisation's pictures (the concept space, the shift kinds, a counterfactual)
codes      the participant codes issued in advance (codes.txt), the only ones accepted
answers    the answers on disk, appended and fsynced, per participant
page       one browser tab: a participant code, the familiarisation, the questions
server     `dfa study serve`: the page for many participants at once
analysis   `dfa study analyse`'s numbers: accuracy, chi-squared, Wilcoxon, the table
models     the mixed-effects model and the exact test by task
figures    accuracy.png, durations.png and answers.rrd
report     the analysis' files: answers.csv, accuracy.md, the figures
cli        the three subcommands
"""
