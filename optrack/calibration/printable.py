"""A printable checkerboard, PDF (vector, exact size) or PNG (with its print resolution).

The pattern matches the board frame of :mod:`optrack.calibration.board`:
(cols + 1) x (rows + 1) squares around the inner corners, the square
diagonally before the first corner dark. Under the pattern the page states
the board (inner corners, square size) and carries a 100 mm bar to check
that the printer did not scale it.
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.errors import UserError
from optrack.io.files import atomic_write_bytes

__all__ = ["PAPER_MM", "board_image", "board_label", "save_printable_board"]

# ISO 216 portrait sizes (width, height) in millimetres.
PAPER_MM = {
    "a4": (210.0, 297.0),
    "a3": (297.0, 420.0),
    "a2": (420.0, 594.0),
    "a1": (594.0, 841.0),
    "a0": (841.0, 1189.0),
    "letter": (215.9, 279.4),
}
MARGIN_MM = 15.0  # white border around the squares
FOOTER_MM = 22.0  # room for the label and the 100 mm bar
BAR_MM = 100.0


class PrintError(UserError):
    """A printable board that cannot be made."""


def board_label(board: Checkerboard) -> str:
    return (
        f"optrack checkerboard: {board.cols}x{board.rows} inner corners "
        f"({board.cols + 1}x{board.rows + 1} squares), square {board.square * 1000:g} mm. "
        "Print at 100% (no scaling); the bar below must measure 100 mm."
    )


def board_image(
    board: Checkerboard, px_per_square: int = 40, margin_squares: float = 1.0
) -> np.ndarray:
    """The pattern alone as a grey uint8 image: pixel centre (u, v) is board point
    ((u + 0.5) / px_per_square - 1 - margin, (v + 0.5) / px_per_square - 1 - margin)
    squares, i.e. the pattern's outer corner is at margin squares from the image edge."""
    margin = int(round(margin_squares * px_per_square))
    width = (board.cols + 1) * px_per_square + 2 * margin
    height = (board.rows + 1) * px_per_square + 2 * margin
    image = np.full((height, width), 255, dtype=np.uint8)
    for j in range(board.rows + 1):
        for i in range(board.cols + 1):
            if (i + j) % 2 == 0:  # square (-1, -1) of the board frame is dark
                y0, x0 = margin + j * px_per_square, margin + i * px_per_square
                image[y0 : y0 + px_per_square, x0 : x0 + px_per_square] = 0
    return image


def _page_mm(board: Checkerboard, paper: str) -> tuple[float, float]:
    pattern_w = (board.cols + 1) * board.square * 1000
    pattern_h = (board.rows + 1) * board.square * 1000
    needed = (pattern_w + 2 * MARGIN_MM, pattern_h + 2 * MARGIN_MM + FOOTER_MM)
    if paper == "fit":
        return max(needed[0], BAR_MM + 2 * MARGIN_MM), needed[1]
    if paper not in PAPER_MM:
        raise PrintError(f"--paper must be fit or one of {', '.join(PAPER_MM)}; got '{paper}'.")
    for width, height in (PAPER_MM[paper], PAPER_MM[paper][::-1]):
        if width >= needed[0] and height >= needed[1]:
            return width, height
    raise PrintError(
        f"a {board.cols}x{board.rows} board with {board.square * 1000:g} mm squares needs "
        f"{needed[0]:.0f}x{needed[1]:.0f} mm; it does not fit on {paper.upper()}. Choose a larger "
        "paper, --paper fit, or smaller squares."
    )


def _squares_mm(board: Checkerboard, page: tuple[float, float]) -> tuple[float, float, float]:
    """Left and top of the pattern on the page (mm) and the square size (mm)."""
    square = board.square * 1000
    pattern_w = (board.cols + 1) * square
    left = (page[0] - pattern_w) / 2
    return left, MARGIN_MM, square


def _pdf(board: Checkerboard, page: tuple[float, float]) -> bytes:
    """A one-page PDF with the squares as filled rectangles (exact size when printed at 100%)."""
    point = 72.0 / 25.4
    width, height = page[0] * point, page[1] * point
    left, top, square = _squares_mm(board, page)
    ops = ["0 g"]
    for j in range(board.rows + 1):
        for i in range(board.cols + 1):
            if (i + j) % 2 == 0:
                x = (left + i * square) * point
                y = height - (top + (j + 1) * square) * point
                ops.append(f"{x:.4f} {y:.4f} {square * point:.4f} {square * point:.4f} re f")
    text_y = height - (top + (board.rows + 1) * square + 8) * point
    label = board_label(board).replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)")
    ops.append(f"BT /F1 7 Tf {left * point:.3f} {text_y:.3f} Td ({label}) Tj ET")
    bar_y = text_y - 10 * point
    ops.append(f"{left * point:.4f} {bar_y:.4f} {BAR_MM * point:.4f} {1.5 * point:.4f} re f")
    ops.append(f"BT /F1 7 Tf {(left + BAR_MM + 3) * point:.3f} {bar_y:.3f} Td (100 mm) Tj ET")
    stream = "\n".join(ops).encode("ascii")
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {width:.3f} {height:.3f}] "
        "/Resources << /Font << /F1 5 0 R >> >> /Contents 4 0 R >>".encode("ascii"),
        b"<< /Length " + str(len(stream)).encode() + b" >>\nstream\n" + stream + b"\nendstream",
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>",
    ]
    out = bytearray(b"%PDF-1.4\n")
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += f"{number} 0 obj\n".encode() + body + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode()
    for offset in offsets:
        out += f"{offset:010d} 00000 n \n".encode()
    out += (
        f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R >>\nstartxref\n{xref}\n%%EOF\n".encode()
    )
    return bytes(out)


def _png(board: Checkerboard, page: tuple[float, float], dpi: int) -> bytes:
    """A PNG of the page at ``dpi``, with its physical resolution recorded (pHYs chunk)."""
    px_per_mm = dpi / 25.4
    width, height = round(page[0] * px_per_mm), round(page[1] * px_per_mm)
    image = np.full((height, width), 255, dtype=np.uint8)
    left, top, square = _squares_mm(board, page)
    for j in range(board.rows + 1):
        for i in range(board.cols + 1):
            if (i + j) % 2 == 0:
                x0 = round((left + i * square) * px_per_mm)
                x1 = round((left + (i + 1) * square) * px_per_mm)
                y0 = round((top + j * square) * px_per_mm)
                y1 = round((top + (j + 1) * square) * px_per_mm)
                image[y0:y1, x0:x1] = 0
    text_y = round((top + (board.rows + 1) * square + 8) * px_per_mm)
    scale = max(0.3, 2.2 * px_per_mm / 30.0)
    words, line = board_label(board).split(" "), ""
    lines = []
    max_width = width - 2 * round(left * px_per_mm)
    for word in words:  # wrap the label to the pattern's width
        trial = f"{line} {word}".strip()
        if cv2.getTextSize(trial, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > max_width and line:
            lines.append(line)
            line = word
        else:
            line = trial
    lines.append(line)
    line_height = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][1] * 1.6
    for n, text in enumerate(lines):
        cv2.putText(
            image,
            text,
            (round(left * px_per_mm), round(text_y + n * line_height)),
            cv2.FONT_HERSHEY_SIMPLEX,
            scale,
            0,
            max(1, round(scale)),
            cv2.LINE_AA,
        )
    bar_y = round(text_y + len(lines) * line_height + 2 * px_per_mm)
    x0 = round(left * px_per_mm)
    image[bar_y : bar_y + max(2, round(1.5 * px_per_mm)), x0 : x0 + round(BAR_MM * px_per_mm)] = 0
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise PrintError("OpenCV could not encode the board as PNG.")
    data = encoded.tobytes()
    per_metre = round(dpi / 0.0254)
    body = b"pHYs" + struct.pack(">IIB", per_metre, per_metre, 1)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    ihdr_end = 8 + 8 + 13 + 4  # signature, IHDR length+type, IHDR data, CRC
    return data[:ihdr_end] + chunk + data[ihdr_end:]


def save_printable_board(
    path: str | os.PathLike[str], board: Checkerboard, paper: str = "fit", dpi: int = 300
) -> tuple[float, float]:
    """Write the board as ``.pdf`` or ``.png``; returns the page size in mm."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".pdf", ".png"):
        raise PrintError(f"--out {path} must end in .pdf or .png.")
    if not 50 <= dpi <= 1200:
        raise PrintError(f"--dpi must be 50-1200; got {dpi}.")
    page = _page_mm(board, paper.lower())
    data = _pdf(board, page) if suffix == ".pdf" else _png(board, page, dpi)
    atomic_write_bytes(path, data)
    return page
