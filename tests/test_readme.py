"""README's "From Python" example, run as a user would: in a fresh folder, in its own process."""

import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def python_block(section: str) -> str:
    text = README.read_text()
    part = text.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", part, flags=re.S)
    assert len(blocks) == 1, f"README's {section} section should hold one python block"
    return blocks[0]


def test_from_python_example_runs(tmp_path):
    code = python_block("From Python")
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    # What the text under the block says it shows: an ok answer, the stop predicted.
    first = res.stdout.splitlines()[0]
    assert first.startswith("ok ") and first.endswith("['t2', 'x2']"), first
    assert "stderr_m" in res.stdout
    for name in ("shot.json", "shot.avi", "shot.truth.csv", "shot.png"):
        assert (tmp_path / name).stat().st_size > 0, name
