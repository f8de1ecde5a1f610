from __future__ import annotations

import json
import re
import struct

import cv2
import numpy as np
import pytest

from optrack.calibration.board import Checkerboard, find_corners
from optrack.calibration.printable import PrintError, save_printable_board
from optrack.cli import main


def test_pdf_page_holds_the_squares_at_their_printed_size(tmp_path):
    board = Checkerboard(9, 6, 0.025)
    path = tmp_path / "board.pdf"
    page = save_printable_board(path, board, "a3")
    data = path.read_bytes()
    assert data.startswith(b"%PDF-1.4") and data.rstrip().endswith(b"%%EOF")
    assert page == (297.0, 420.0)
    squares = re.findall(rb"([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+) re f", data)
    sides = {round(float(s[2]) * 25.4 / 72, 3) for s in squares[:-1]}  # the last is the bar
    assert sides == {25.0}
    assert len(squares) - 1 == (10 * 7 + 1) // 2  # every other square of 10x7 is dark
    assert b"9x6 inner corners" in data and b"square 25 mm" in data


def test_png_records_its_resolution_and_its_corners_are_a_square_apart(tmp_path):
    board = Checkerboard(9, 6, 0.02)
    path = tmp_path / "board.png"
    save_printable_board(path, board, "fit", dpi=200)
    data = path.read_bytes()
    at = data.index(b"pHYs")
    per_metre_x, per_metre_y, unit = struct.unpack(">IIB", data[at + 4 : at + 13])
    assert unit == 1 and per_metre_x == per_metre_y == round(200 / 0.0254)
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    corners = find_corners(image, board)
    assert corners is not None
    spacing_mm = np.linalg.norm(corners[1] - corners[0]) / 200 * 25.4
    assert spacing_mm == pytest.approx(20.0, abs=0.15)


def test_a_board_too_big_for_the_paper_is_refused(tmp_path):
    with pytest.raises(PrintError, match="does not fit on A4"):
        save_printable_board(tmp_path / "b.pdf", Checkerboard(9, 6, 0.05), "a4")
    with pytest.raises(PrintError, match=r"\.pdf or \.png"):
        save_printable_board(tmp_path / "b.svg", Checkerboard(9, 6, 0.05))


def test_board_cli_reports_the_page(tmp_path, capsys):
    out = tmp_path / "board.pdf"
    assert (
        main(
            ["calibrate", "board", "--board", "7x4", "--square", "0.1", "--out", str(out), "--json"]
        )
        == 0
    )
    payload = json.loads(capsys.readouterr().out)
    assert payload["page_mm"] == [830.0, 552.0]
    assert "7x4 inner corners" in payload["label"]
