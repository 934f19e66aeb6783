"""`dfa bench`: every speed figure measured on this machine, each against a baseline or a bound
timed in the same run, written to benchmarks/latest.md.

run.py       run_bench: the table of figures, printed and written
search.py    the search against a naive one-candidate loop and the forward-pass bound
tabletop.py  the tabletop's edit + render and search targets
prior.py     the learned search prior against enumeration and the first-step prior
costs.py     per world: render throughput, finetuning, recording size, one experiment run
page.py      the web page in Chromium: load, slider latency, finetune round trip
timing.py    best_of and the machine's name
args.py      BenchArgs, its options
"""
