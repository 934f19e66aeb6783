"""`dfa study`: the paper's user study run on the page, with and without explanations.

args       the options of `dfa study new|serve|analyse`
protocol   study.toml read and checked; each participant's balanced plan of questions
freeze     `dfa study new`: every task made once and frozen in the study folder
intro      the familiarisation's pictures (the concept space, the shift kinds, a counterfactual)
codes      the participant codes issued in advance (codes.txt), the only ones accepted
answers    the answers on disk, appended and fsynced, per participant
page       one browser tab: a participant code, the familiarisation, the questions
server     `dfa study serve`: the page for many participants at once
analysis   `dfa study analyse`: accuracy, chi-squared, Wilcoxon, answers.csv
figures    accuracy.png and answers.rrd
cli        the three subcommands
"""
