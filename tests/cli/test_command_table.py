"""`fahv` imports only the module of the command it runs: the command table is complete,
and `fahv simulate` starts without matplotlib, Dask or the design pipeline, `fahv verify`
without cvxpy."""

import subprocess
import sys

from fahv.cli import COMMANDS, build_parser


def _commands(parser) -> set[str]:
    sub = next(a for a in parser._actions if a.dest == "command")
    return set(sub.choices)


def test_the_command_table_names_every_subcommand_once():
    assert _commands(build_parser()) == set(COMMANDS)
    for command, module in COMMANDS.items():  # a command's own parser holds it
        assert command in _commands(build_parser(command)), (command, module)
    assert _commands(build_parser("no-such-command")) == set(COMMANDS)


def test_simulate_leaves_the_heavy_modules_of_other_commands_unloaded():
    code = ("import sys; from fahv.cli import build_parser; build_parser('simulate'); "
            "print(sorted(m for m in ('matplotlib', 'dask', 'fahv.design.pipeline', "
            "'fahv.campaign.engine', 'scipy.stats') if m in sys.modules))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_verify_loads_neither_the_lmi_solver_nor_dask():
    """`fahv verify` re-checks stored arrays: its command and the checks it calls
    (fahv.certificate.verify and the synthesis modules' exact checks) import no cvxpy
    (1.5-2 s of every verify's start) and no Dask."""
    heavy = "('cvxpy', 'dask', 'fahv.design.pipeline')"
    code = ("import sys; from fahv.cli import build_parser; build_parser('verify'); "
            "import fahv.certificate.verify, fahv.synthesis.nominal, fahv.synthesis.offline_rmpc, "
            "fahv.synthesis.rpi_level; "
            f"print(sorted(m for m in {heavy} if m in sys.modules))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
