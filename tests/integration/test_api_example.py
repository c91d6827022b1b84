"""The worked example of docs/api.md, run as written (with this test's testbed name)."""

import os
import re

from topology.kernel import netns

DOC = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "api.md")


def test_the_worked_example_of_the_api_runs(tb_name):
    text = open(DOC).read().split("## Worked example", 1)[1]
    code = re.search(r"```python\n(.*?)```", text, re.S)[1]
    assert 'NAME = "demo"' in code
    exec(compile(code.replace('NAME = "demo"', f'NAME = "{tb_name}"'), "docs/api.md", "exec"), {})
    assert not [ns for ns in netns.list_names() if ns.startswith(f"tb-{tb_name}-")]
