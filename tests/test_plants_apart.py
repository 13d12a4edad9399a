"""The test plants stay apart from the product: they import nothing from hystcli, the installed
package holds none of them, and `hyst sim-robot` serves them only from a file it is given."""
from __future__ import annotations

import ast
import fnmatch
import re
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.cli.device_cmds import _file_plant

ROOT = Path(__file__).resolve().parents[1]
PLANTS = ROOT / "bench" / "plants"
LIVE = PLANTS / "live.py"


def _imported(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports (absolute imports; relative ones stay inside
    the plants' package)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_the_plants_import_nothing_from_the_code_under_test():
    files = sorted(PLANTS.rglob("*.py"))
    # the zoo's modules and the wild plant are all read: an empty glob would pass anything
    assert {"plants.py", "catheters.py", "wild.py", "live.py"} <= {f.name for f in files}
    offenders = {f.relative_to(ROOT).as_posix(): sorted(n for n in _imported(f) if n.startswith("hystcli"))
                 for f in files}
    assert not {f: n for f, n in offenders.items() if n}, offenders


def test_the_ast_reading_sees_an_import_of_the_product(tmp_path):
    # the check above can fail: the same reading finds hystcli in a file that imports it
    f = tmp_path / "p.py"
    f.write_text("import numpy\nfrom hystcli.core.params import KnobModel\n")
    assert "hystcli" in _imported(f)


def test_the_package_discovery_leaves_the_plants_out_of_the_wheel():
    # setuptools builds the wheel from the packages pyproject.toml's find-include patterns name
    # (.ci/run also builds the wheel and lists its files)
    text = (ROOT / "pyproject.toml").read_text()
    section = text.split("[tool.setuptools.packages.find]", 1)[1].split("\n[", 1)[0]
    include = re.findall(r'"([^"]+)"', re.search(r"include\s*=\s*\[(.*?)\]", section, re.S).group(1))
    assert include == ["hystcli*"]
    packages = {".".join(d.relative_to(ROOT).parts) for d in (f.parent for f in ROOT.rglob("__init__.py"))
                if any(fnmatch.fnmatch(".".join(d.relative_to(ROOT).parts), pat) for pat in include)}
    assert "hystcli" in packages and "hystcli.core" in packages
    assert not [p for p in packages if "zoo" in p or "plants" in p], packages


def test_sim_robot_builds_a_plant_from_the_file_it_is_given():
    plant = _file_plant(f"{LIVE}:3::2.5")
    assert plant.knobs == (1,) and plant.truth.offset == pytest.approx(2.5, abs=1e-12)
    assert "plants.zoo.plants" in sys.modules  # loaded from the bench, not from hystcli


@pytest.mark.parametrize("spec, message", [(f"{LIVE}:x", "SEED"), (f"{LIVE}:3:nofamily", "FAMILY"),
                                           (str(ROOT / "nothing.py") + ":3", "not a Python file")])
def test_sim_robot_refuses_a_plant_it_cannot_build_as_a_usage_error(spec, message):
    with pytest.raises(typer.BadParameter, match=message):
        _file_plant(spec)
    res = CliRunner().invoke(app, ["sim-robot", "--plant", spec])
    assert res.exit_code == 2 and "--plant" in res.output
