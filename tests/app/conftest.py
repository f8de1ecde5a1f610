"""Qt is configured as the application configures it, before pytest-qt makes its QApplication;
and an embedded site of its own for the tests that start one."""

import pytest
import yaml

from app.main import configure_qt
from tests.conftest import free_port

configure_qt()

# A short venue: rendered once per computer (cached by optrack.runtime.site), then looped.
VENUE = {"scenario": "mixed", "seed": 0, "venue_seconds": 4.0}


@pytest.fixture(scope="session")
def site_config(tmp_path_factory):
    """The configuration of a site on its own loopback port (other sites on this computer
    are left alone), its venue rendered beforehand so that timings are the site's start."""
    from optrack.runtime.venue import venue_recording

    venue_recording(VENUE["scenario"], VENUE["seed"], VENUE["venue_seconds"])
    path = tmp_path_factory.mktemp("site") / "site.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {**VENUE, "name": "guitest", "report_s": 0.0},
                "outputs": {"udp": ""},
            }
        )
    )
    return path
