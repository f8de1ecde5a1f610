"""optrack's operator application (PySide6 + pyqtgraph).

The application only shows what ``optrack`` computes and sends the
operator's intent back; it imports ``optrack``, never the reverse.
"""
