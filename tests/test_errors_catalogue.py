"""The bad-input catalogue (tools/errors_catalogue.py, docs/errors.md): every case fails with its documented error
type and one-line message, leaves no cache behind and keeps an earlier cache as it was; the page lists exactly the
catalogue's cases with the messages the cases produce."""

from __future__ import annotations

import errors_catalogue as cat
import pytest

DOC_MESSAGES = cat.doc_messages(cat.DOC.read_text()) if cat.DOC.exists() else {}


def test_catalogue_size_and_page():
    """At least 40 distinct bad inputs (ids unique); docs/errors.md has one row per case, in the same order."""
    ids = [c.id for c in cat.CASES]
    assert len(ids) >= 40
    assert len(set(ids)) == len(ids)
    assert list(DOC_MESSAGES) == ids, "docs/errors.md is out of date: run python tools/errors_catalogue.py"


@pytest.mark.parametrize("case", cat.CASES, ids=[c.id for c in cat.CASES])
def test_case(case, tmp_path):
    """The case raises its error type (the command line: exit 1, one 'pdsim: error:' line, no traceback) with the
    documented fragments, writes nothing but its inputs and leaves an earlier cache byte for byte; its message is the
    one on docs/errors.md."""
    reason = cat.skip_reason(case)
    if reason:
        pytest.skip(reason)
    message = cat.capture(case, tmp_path)
    assert DOC_MESSAGES.get(case.id) == message, (
        "docs/errors.md shows another message for this case: run python tools/errors_catalogue.py"
    )
