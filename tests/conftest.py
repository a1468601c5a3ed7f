"""The suite's fixtures; the helpers the test modules share are in tests/helpers.py."""

import pytest


@pytest.fixture(autouse=True)
def history_in_tmp(tmp_path_factory, monkeypatch):
    """Every test files its trials in a history of its own (HIL_HISTORY, inherited by the hil processes it
    starts) and spools them in a data directory of its own (XDG_DATA_HOME), never the user's."""
    path = tmp_path_factory.mktemp("history") / "history.sqlite"
    monkeypatch.setenv("HIL_HISTORY", str(path))
    monkeypatch.setenv("XDG_DATA_HOME", str(path.parent / "data"))
    return path


@pytest.fixture
def udp_multicast_alone():
    """Holds a host-wide lock for the test: python-can's logger (a third-party process) hears every
    multicast group on python-can's UDP port, so two tests on different groups would hear each other."""
    import fcntl
    import tempfile
    from pathlib import Path

    with open(Path(tempfile.gettempdir()) / "turntable-hil-udp-multicast.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield
