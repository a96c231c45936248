"""A baud or I2C clock the readout board cannot make is refused before any work, by ``magfab check`` and ``magfab
build`` alike, with the line the firmware's own settings would give (it used to pass the check and fail the build
with exit 1, deep in its worker): over the spec's whole baud and I2C-clock ranges, for each board."""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import derive, load_spec
from magfab.check.links import BAUD_ERROR_LIMIT, serial_links
from magfab.cli import main
from magfab.errors import SpecError
from magfab.export import firmware
from magfab.spec import parse_spec

BASE = load_spec(None)
BOARDS = [None, "nano", "pico", "qtpy-rp2040", "xiao-rp2040"]


def _design(baud: int, i2c_hz: int, board: str | None):
    fw = BASE.firmware.model_copy(update={"baud": baud, "i2c_hz": i2c_hz})
    update = {"firmware": fw, "board": None if board is None else parse_spec(f'[board]\nboard = "{board}"\n').board}
    return derive(BASE.model_copy(update=update))


def _refusal(call) -> str | None:
    try:
        call()
    except SpecError as exc:
        return str(exc)
    return None


@settings(max_examples=300, deadline=None)
@given(st.integers(9600, 2_000_000), st.integers(10_000, 1_000_000), st.sampled_from(BOARDS))
def test_the_check_refuses_exactly_what_the_firmware_cannot_make(baud, i2c_hz, board):
    design = _design(baud, i2c_hz, board)
    early = _refusal(lambda: serial_links(design))
    assert early == _refusal(lambda: firmware.image_settings(design))
    if board in (None, "nano"):
        error = abs(16e6 / (8 * max(1, round(16e6 / (8 * baud)))) / baud - 1)
        assert (early is not None) == (error > BAUD_ERROR_LIMIT or round(16e6 / (8 * baud)) - 1 > 4095)
    else:
        assert early is None  # USB: no baud


@pytest.mark.parametrize(("board", "refused"), [("", True), ('[board]\nmcu = "rp2040"\n', False)])
def test_check_and_build_give_the_same_line_and_exit_2(tmp_path, board, refused):
    spec = tmp_path / "fast.toml"
    spec.write_text(f'name = "fast"\n[firmware]\nbaud = 1500000\n{board}')
    if not refused:
        assert CliRunner().invoke(main, ["check", str(spec)]).exit_code == 0
        return
    assert "firmware.baud = 1500000" in _both_refuse(spec)


def _both_refuse(spec) -> str:
    """``magfab check`` and ``magfab build`` of ``spec`` (alone in its folder): each exit 2 with the same last line,
    nothing written; that line."""
    lines = []
    for args in (["check", str(spec)], ["build", str(spec), "--out", str(spec.parent / "out")]):
        run = CliRunner().invoke(main, args)
        assert run.exit_code == 2, run.output
        lines.append(run.output.strip().splitlines()[-1])
    assert lines[0] == lines[1]
    assert sorted(p.name for p in spec.parent.iterdir()) == [spec.name]
    return lines[0]


@pytest.mark.parametrize("board", BOARDS)
def test_a_second_i2c_bus_needs_an_rp2040_and_check_and_build_say_so_alike(tmp_path, board):
    """``array.buses = 2`` on a board with one I2C controller (the Uno's and the Nano's ATmega328P): ``magfab check``
    and ``magfab build`` give the same one line naming array.buses, exit 2, nothing written; an RP2040 board passes
    the check (its two controllers: the build's test is tests/board/test_array_board.py)."""
    spec = tmp_path / "split.toml"
    chosen = "" if board is None else f'[board]\nboard = "{board}"\n'
    spec.write_text(f'name = "split"\n[array]\nrows = 1\ncols = 2\npitch_mm = 14\nbuses = 2\n{chosen}')
    if board in ("pico", "qtpy-rp2040", "xiao-rp2040"):
        assert CliRunner().invoke(main, ["check", str(spec)]).exit_code == 0
        return
    line = _both_refuse(spec)
    assert "array.buses = 2" in line and "rp2040" in line
