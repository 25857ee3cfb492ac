"""The install puts one import name, cuespin, into site-packages (issue 13)."""

import subprocess
import sys
import zipfile
from importlib.metadata import distribution
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("physics", "data_gen", "render", "track", "fit", "recover", "pipeline")


def test_installed_top_level_is_cuespin_only():
    top = distribution("cuespin").read_text("top_level.txt")
    assert top is not None and top.split() == ["cuespin"]


def test_stages_import_as_subpackages():
    import cuespin

    for stage in STAGES:
        mod = __import__(f"cuespin.{stage}", fromlist=["_"])
        assert mod.__name__ == f"cuespin.{stage}"
    assert cuespin.__version__


@pytest.mark.slow
def test_regular_wheel_holds_only_cuespin(tmp_path):
    """A regular (non-editable) build maps the root folders under cuespin/."""
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
                   check=True, capture_output=True)
    wheel = next(tmp_path.glob("cuespin-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"cuespin"}
    for stage in STAGES:
        assert f"cuespin/{stage}/__init__.py" in names
