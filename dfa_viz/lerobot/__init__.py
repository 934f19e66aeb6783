"""dfa's data as LeRobotDatasets, and LeRobotDatasets in Rerun (the format: sim.lerobot).

args.py      ExportArgs and ViewArgs, the options of `dfa export lerobot` and `dfa view`
episodes.py  a run of the loop as episodes, one per trajectory, with dfa's own columns
sources.py   what `dfa export lerobot` reads: a page session, a sweep, a q2 results folder
export.py    `dfa export lerobot` and `dfa run --lerobot DIR`
view.py      `dfa view DIR`: every episode of a dataset in one .rrd
"""
