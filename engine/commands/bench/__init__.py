"""`lirm bench`: the benchmarks, one module per `lirm bench NAME` (see `lirm.engine.commands`)."""

from __future__ import annotations

from . import app_idle, app_refine, capacity, capture, export, exposure, lighting, model, refine, relight, render, suggest, synth, train, trajectory, update_order

BENCHMARKS = (model, capacity, export, suggest, trajectory, refine, lighting, relight, exposure, update_order, synth, train, render, capture, app_idle, app_refine)  # as listed


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("bench", help="benchmarks")
    bench_sub = parser.add_subparsers(title="benchmarks", metavar="BENCH", required=True)
    for benchmark in BENCHMARKS:
        benchmark.add_parser(bench_sub)
    for name, command in bench_sub.choices.items():  # for messages: `lirm bench NAME --help`
        command.set_defaults(command=f"bench {name}")
