"""Start the operator application: ``optrack gui`` (and ``make run``).

Which site the window shows:

* by default, the embedded site: the window starts ``optrack run --headless``
  (with ``--config`` when given) and joins its bus on this computer;
* ``--join``: a site already running on this computer (``optrack run``
  starts the window this way; a window started by it joins it too);
* ``--connect ENDPOINTS``: a site elsewhere on the network, through Zenoh
  endpoints such as ``tcp/192.168.1.10:7447``;
* ``--no-site``: none ("No site connected").
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from app.cli import add_gui_options
from optrack.runtime.display import HEADLESS_HINT, display_problem


def configure_qt() -> None:
    """Settings Qt needs before the QApplication exists.

    All OpenGL views share one context group: pyqtgraph compiles each shader
    once per process, so a second 3D view (or a view re-created) must be able
    to use the first one's programs.
    """
    from PySide6.QtCore import QCoreApplication, Qt

    QCoreApplication.setAttribute(Qt.ApplicationAttribute.AA_ShareOpenGLContexts)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="optrack gui", description="Open the operator application."
    )
    add_gui_options(parser)
    return parser


def wants_embedded_site(args: argparse.Namespace) -> bool:
    """Whether the window starts a site of its own (no --no-site, --connect or --join, and
    not started by 'optrack run')."""
    from optrack.runtime.node import PARENT_ENV  # set by 'optrack run' in what it starts

    return not (args.no_site or args.connect or args.join or os.environ.get(PARENT_ENV))


def start_embedded_site(args: argparse.Namespace):  # noqa: ANN201 - a Qt object
    """The embedded site, started at once: its processes start while the window is built."""
    from app.embedded_site import EmbeddedSite

    embedded = EmbeddedSite(args.config)
    embedded.start()
    return embedded


def choose_source(args: argparse.Namespace, window, embedded=None):  # noqa: ANN001, ANN201
    """Make the window's source as the options say; start the embedded site if needed
    (``embedded``: one already started by :func:`start_embedded_site`)."""
    import threading

    from app.source import SiteSource

    if args.no_site:
        window.log_panel.append("info", "No site connected (--no-site).")
        return SiteSource(window)
    from app.bus_source import BusSource
    from optrack.runtime.config import load_node_config
    from optrack.runtime.node import PARENT_ENV  # set by 'optrack run' in what it starts

    config = load_node_config(args.config)
    site = args.site or str(config["site"].name)
    bus = config["bus"]
    if args.connect:
        bus.update({"mode": "peer", "connect": args.connect})
        return BusSource(site, bus, window)
    if args.join or os.environ.get(PARENT_ENV):
        return BusSource(site, bus, window)
    if embedded is None:
        embedded = start_embedded_site(args)
    embedded.setParent(window)
    alive = threading.Event()
    alive.set()
    embedded.ended.connect(lambda code, last: alive.clear())
    source = BusSource(
        site,
        bus,
        window,
        retry_while=alive,
        label=f"Embedded site '{site}' on this computer",
    )
    window.run_embedded_site(embedded, stop_timeout_s=3 * float(config["site"].stop_timeout_s))
    return source


def main(argv: Sequence[str] | None = None) -> int:
    return run(build_parser().parse_args(argv))


def run(args: argparse.Namespace) -> int:
    """Open the window as the parsed options of ``optrack gui`` say; its exit status."""
    problem = display_problem()
    if problem is not None:
        print(HEADLESS_HINT.format(reason=problem), file=sys.stderr)
        return 1

    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from optrack.errors import UserError

    configure_qt()
    app = QApplication.instance() or QApplication([sys.argv[0]])
    app.setApplicationName("optrack")
    # the site's processes start while this one imports and builds the window
    embedded = start_embedded_site(args) if wants_embedded_site(args) else None
    from app.main_window import MainWindow

    window = MainWindow()
    try:
        window.set_source(choose_source(args, window, embedded))
    except UserError as error:
        if embedded is not None:
            embedded.stop(timeout_s=5.0)
        print(f"optrack gui: {error}", file=sys.stderr)
        return 1
    window.show()
    status = {"code": 0}

    def screenshot() -> None:
        if not window.screenshot().save(args.screenshot):
            print(
                f"optrack gui: could not save the screenshot to {args.screenshot}; check that its folder exists and is writable.",
                file=sys.stderr,
            )
            status["code"] = 1

    if args.quit_after is not None:
        delay_ms = max(0, int(args.quit_after * 1000))
        if args.screenshot:
            QTimer.singleShot(max(0, delay_ms - 200), screenshot)
        QTimer.singleShot(delay_ms, window.close)
    elif args.screenshot:
        QTimer.singleShot(1500, screenshot)
    app.exec()
    window.shut_down()
    return status["code"]


if __name__ == "__main__":
    sys.exit(main())
