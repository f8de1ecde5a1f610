"""Start the operator application: ``optrack gui`` (and ``make run``)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from app.display import HEADLESS_HINT, display_problem


def configure_qt() -> None:
    """Settings Qt needs before the QApplication exists.

    All OpenGL views share one context group: pyqtgraph compiles each shader
    once per process, so a second 3D view (or a view re-created) must be able
    to use the first one's programs.
    """
    from PySide6.QtCore import QCoreApplication, Qt

    QCoreApplication.setAttribute(Qt.ApplicationAttribute.AA_ShareOpenGLContexts)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="optrack gui", description="Open the operator application."
    )
    parser.add_argument(
        "--screenshot", metavar="PNG", help="save a screenshot of the window to this file"
    )
    parser.add_argument(
        "--quit-after", type=float, metavar="S", help="close the window after S seconds"
    )
    args = parser.parse_args(argv)

    problem = display_problem()
    if problem is not None:
        print(HEADLESS_HINT.format(reason=problem), file=sys.stderr)
        return 1

    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    configure_qt()
    app = QApplication.instance() or QApplication([sys.argv[0]])
    app.setApplicationName("optrack")
    window = MainWindow()
    window.show()
    status = {"code": 0}

    def screenshot() -> None:
        if not window.grab().save(args.screenshot):
            print(
                f"optrack gui: could not save the screenshot to {args.screenshot}; check that its folder exists and is writable.",
                file=sys.stderr,
            )
            status["code"] = 1

    if args.quit_after is not None:
        delay_ms = max(0, int(args.quit_after * 1000))
        if args.screenshot:
            QTimer.singleShot(max(0, delay_ms - 200), screenshot)
        QTimer.singleShot(delay_ms, app.quit)
    elif args.screenshot:
        QTimer.singleShot(1500, screenshot)
    app.exec()
    return status["code"]


if __name__ == "__main__":
    sys.exit(main())
