"""Run the README's quick-start example (the first ```python block under "## Quick start").

Used to check an installed wheel: run it from any directory, with any interpreter that has
triaxcal installed. Exits non-zero if the example raises.
"""

import pathlib
import re
import sys

readme = pathlib.Path(__file__).resolve().parent.parent / "README.md"
text = readme.read_text(encoding="utf-8")
section = text.split("## Quick start", 1)[1]
code = re.search(r"```python\n(.*?)```", section, re.S)
if code is None:
    sys.exit("no python block under '## Quick start' in README.md")
exec(compile(code.group(1), "README.md quick start", "exec"), {"__name__": "__main__"})
