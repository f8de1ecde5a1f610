"""Qt is configured as the application configures it, before pytest-qt makes its QApplication."""

from app.main import configure_qt

configure_qt()
