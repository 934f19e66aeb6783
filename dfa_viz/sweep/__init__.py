"""`dfa sweep`: what breaks a policy before a user meets it (search.sweep run and shown).

args       SweepArgs, the options of `dfa sweep`
run        run_sweep(SweepArgs): the sweep on the backends with a progress bar, its files
           written; page_sweep for the page's Sweep tab
tables     sweep.csv and the rich tables printed in the terminal
figures    the heatmap (slot.concept x value, with where each cell lies) and the bars
recording  sweep.rrd: heatmap, bars, ranking, the worst edited rollouts beside unedited
"""
