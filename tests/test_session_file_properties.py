"""Crafted session files never crash `Session.load` / `estimate` (issue 17). Property-based
(hypothesis, bounded examples; GRAPHLOC_FUZZ_EXAMPLES=2000 for a deeper search): a saved session
with valid checksums but any leaf of its JSON replaced loads and estimates, or raises a ValueError
naming the file -- never another exception or a crash inside GTSAM."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import EXAMPLES, FAST, JSON_LEAVES, set_json_leaf
from helpers import json_paths as _json_paths


@settings(FAST, max_examples=EXAMPLES or 25)
@given(data=st.data(), mode=st.sampled_from(["batch", "online"]))
def test_crafted_session_files_load_or_raise_value_error(tmp_path_factory, data, mode):
    """A session file with valid checksums but any leaf of its JSON replaced (as a crafted file
    would be): load and estimate give a session or a ValueError naming the file -- never
    another exception or a crash inside GTSAM."""
    import json

    from graphloc.session import Session, SessionConfig
    from test_session import _every_saved_type, _rewrite

    factors, values = _every_saved_type()
    session = Session(SessionConfig(mode=mode))
    session.add(factors, values, time=0.0)
    path = tmp_path_factory.mktemp("s") / "s.json"
    session.save(path)
    payload = json.loads(path.read_bytes().split(b"\n", 1)[1])
    paths = sorted(_json_paths(payload), key=str)
    edits = data.draw(
        st.lists(st.tuples(st.sampled_from(paths), JSON_LEAVES), min_size=1, max_size=3)
    )

    def edit(doc):
        for where, value in edits:
            set_json_leaf(doc, where, value)
        return doc

    _rewrite(path, edit)
    try:
        loaded = Session.load(path)
        loaded.estimate()
    except ValueError as exc:
        assert str(path) in str(exc) or str(exc).startswith("Session.")
