"""Every run option has its line in the guide's option list (docs/architecture.md, "Adding
a run option"): the options come from the one table, RunConfig's fields, so an option added
there without its line fails here."""

import re
from pathlib import Path

import pytest

from testbed import PROJECT_ROOT
from testbed.files.runconfig import OPTIONS

# Where the options are listed: the guide's section on a run by hand (the README links it).
GUIDE = Path(PROJECT_ROOT) / "docs" / "guide.md"
SECTION = "## One run by hand"


def option_list() -> str:
    text = GUIDE.read_text()
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    return text[start : end if end >= 0 else len(text)]


def test_the_table_is_read_whole():
    assert len(OPTIONS) >= 33 and {"robots", "time_scale", "view"} <= {o.name for o in OPTIONS}


@pytest.mark.parametrize("flag", [o.flag for o in OPTIONS])
def test_every_run_option_has_its_line(flag):
    found = re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", option_list())
    assert found, f"{flag}: a run option with no line in docs/guide.md's '{SECTION}'"
