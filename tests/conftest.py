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


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's worker reads the groups
def pytest_collection_modifyitems(config, items):
    """Under ``pytest -n`` (``--dist loadgroup``) the tests that share a module-scoped fixture of their own module
    run on one worker, so its trials run once, not once a worker; a test already in a group keeps it."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        if info is None or item.get_closest_marker("xdist_group") is not None:
            continue
        module = item.module.__name__
        if any(d.scope == "module" and d.func.__module__ == module for defs in info.name2fixturedefs.values()
               for d in defs):
            item.add_marker(pytest.mark.xdist_group(module))
    if getattr(config.option, "loadgroup", False):
        _grouped_ids(items)


def _grouped_ids(items):
    """Each grouped test's id ends in ``@group``, which is how pytest-xdist's scheduler tells its group: pytest
    9.2's structured ids leave out the suffix pytest-xdist 3.8 writes (pytest-dev/pytest-xdist#1386), and every
    test would go to any worker (an older pytest has no ``_id``, and pytest-xdist adds the suffix itself)."""
    for item in items:
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        node_id = getattr(item, "_id", None)
        if names and hasattr(node_id, "parse") and "@" not in item.nodeid:
            item._id = node_id.parse(f"{item.nodeid}@{'_'.join(names)}")
