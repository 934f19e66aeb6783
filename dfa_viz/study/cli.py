"""The `dfa study` subcommands: new, serve, analyse (their configs: dfa_viz.configs)."""

from __future__ import annotations

import time

from dfa_viz.study.args import AnalyseStudyArgs, NewStudyArgs, ServeStudyArgs
from sim.core import UserError


def study_new(args: NewStudyArgs) -> None:
    from dfa_viz.study.codes import CODES, issue
    from dfa_viz.study.freeze import freeze
    from dfa_viz.study.protocol import Protocol

    issue(args.participants)  # a bad count: one line, before anything is made

    if args.protocol is None:
        protocol, text = Protocol().check(), None
    else:
        protocol = Protocol.load(args.protocol)
        text = args.protocol.read_text()
    t0 = time.perf_counter()
    frozen = freeze(
        protocol,
        args.out,
        protocol_text=text,
        progress=lambda s: print(f"  {s}", flush=True),
        participants=args.participants,
    )
    print(
        f"dfa study: {frozen.tasks} tasks of {', '.join(frozen.worlds)} frozen in {frozen.folder} "
        f"({len(protocol.slots)} questions per participant; {time.perf_counter() - t0:.0f} s)"
    )
    print(
        f"dfa study: {len(frozen.codes)} participant codes, one for each participant, in this "
        f"order (the page accepts no other; also in {frozen.folder / CODES}):"
    )
    for i in range(0, len(frozen.codes), 6):
        print("  " + "  ".join(frozen.codes[i : i + 6]))
    print(f"dfa study: next, dfa study serve {frozen.folder}")


def study_serve(args: ServeStudyArgs) -> None:
    from dfa_viz.app.address import serving_port

    serving_port(args.host, args.port)  # bad --host/--port: one line, before anything else
    from dfa_viz.study.server import serve_study

    serve_study(args.folder, port=args.port, host=args.host)


def study_analyse(args: AnalyseStudyArgs) -> None:
    from dfa_viz.study.analysis import table_md
    from dfa_viz.study.report import write_analysis

    if not args.folder.is_dir():
        raise UserError(f"{args.folder}: no such study folder")
    a = write_analysis(args.folder)
    print(table_md(a))
    for path in a.files:
        print(f"  {path}")
