"""The commands of the `lirm` command line, one module per command: `lirm NAME` is in `NAME.py`
(`lirm bench NAME` in `bench/NAME.py`, a dash in the name an underscore in the module's).

Each module has `add_parser(subparsers)`, which adds the command's argparse parser with its options
and help and `set_defaults(run=run)`, and `run(args) -> int`, which does the work and returns the exit
code. Problems are raised as the errors of `lirm.engine.errors`; `lirm.engine.cli.main` turns them
into one sentence and an exit code. What several commands share (option ranges, checks before any
work starts, progress bars, the held-out sets) is in `common.py`; a helper of one command stays in
its module. Heavy modules (torch, moderngl, pycolmap, ...) are imported inside `run`, never at the
top, so that `lirm --help` starts fast.

To add a command: write `NAME.py` with `add_parser` and `run`, and call its `add_parser` in
`lirm.engine.cli.build_parser` (or in `bench/__init__.py` for a benchmark) where it should be listed
in `lirm --help`; name the options to lower when it runs out of memory in `cli.MEMORY_OPTIONS`.
"""
