"""The notebooks run end to end (nbclient, a kernel on this interpreter), are committed without outputs, and
``import holoslam`` is cheap: its public names are lazy and pull in no heavy module at import time."""

from __future__ import annotations

import importlib
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from repo_paths import REPO

import holoslam

NOTEBOOK_DIR = REPO / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
HEAVY = ("gtsam", "cv2", "mcap", "matplotlib", "networkx", "scipy", "skimage", "yaml", "mcap_ros2")


# ------------------------------------------------------------------------------------------ import holoslam


def _fresh(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout


def test_import_holoslam_imports_no_heavy_module():
    out = _fresh(
        "import json, sys; before = set(sys.modules); import holoslam; "
        "print(json.dumps(sorted(m for m in set(sys.modules) - before)))"
    )
    new = json.loads(out)
    heavy = [m for m in new if m.split(".")[0] in HEAVY]
    assert heavy == [], f"import holoslam imported {heavy}"
    # only the package itself: no submodule is imported eagerly
    assert [m for m in new if m.startswith("holoslam")] == ["holoslam"]


def test_lazy_name_imports_its_module_only_on_access():
    out = _fresh(
        "import json, sys, holoslam; a = 'holoslam.config' in sys.modules; cfg = holoslam.RunConfig(); "
        "b = 'holoslam.config' in sys.modules; print(json.dumps([a, b, type(cfg).__module__]))"
    )
    assert json.loads(out) == [False, True, "holoslam.config"]


def test_every_public_name_resolves_to_its_module_object():
    for name, module in holoslam._LAZY.items():
        assert getattr(holoslam, name) is getattr(importlib.import_module(module), name), name
    for sub in holoslam.SUBMODULES:
        assert getattr(holoslam, sub) is importlib.import_module(f"holoslam.{sub}"), sub
    assert set(holoslam.__all__) == {"__version__", "SUBMODULES", *holoslam._LAZY}
    assert set(holoslam._LAZY) | set(holoslam.SUBMODULES) <= set(dir(holoslam))
    # ``from holoslam import X`` goes through the same lazy path
    from holoslam import load_run, run, viz

    assert run is importlib.import_module("holoslam.pipeline").run
    assert load_run.__module__ == "holoslam.io.run_folder"
    assert viz.__name__ == "holoslam.viz"


def test_unknown_attribute_is_an_attribute_error_that_lists_the_api():
    with pytest.raises(AttributeError, match=r"no attribute 'runn'.*RunConfig.*submodules: .*viz"):
        holoslam.runn  # noqa: B018
    assert not hasattr(holoslam, "definitely_not_a_name")


# ---------------------------------------------------------------------------------------- notebooks: static


def test_the_four_notebooks_exist():
    names = [p.name for p in NOTEBOOKS]
    assert names == [
        "01_quickstart.ipynb",
        "02_dead_reckoning_vs_optimised.ipynb",
        "03_topology_holographic_planning.ipynb",
        "04_victoria_park.ipynb",
    ]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_valid_committed_without_outputs_and_uses_the_public_api(path):
    import nbformat

    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and any(c.cell_type == "markdown" for c in nb.cells)
    for c in code:
        assert c.outputs == [] and c.execution_count is None, (
            f"{path.name}: strip the outputs before committing"
        )
    src = "\n".join(c.source for c in code)
    # public API only: no private holoslam name (a leading underscore) is imported or used
    private = re.findall(r"holoslam(?:\.\w+)*\._\w+|from holoslam[\w.]* import [^\n]*\b_\w+", src)
    assert private == [], f"{path.name} uses private names {private}"


# -------------------------------------------------------------------------------------- notebooks: executed


def _kernel_manager(tmp_path: Path):
    """A kernel on this very interpreter (the venv), from a kernelspec written into ``tmp_path``: works in a fresh
    venv without any user-level kernelspec and never picks another Python."""
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager

    spec = tmp_path / "kernels" / "holoslam-test"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(
        json.dumps(
            {
                "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
                "display_name": "holoslam test kernel",
                "language": "python",
            }
        )
    )
    ksm = KernelSpecManager(kernel_dirs=[str(tmp_path / "kernels")])
    return KernelManager(kernel_name="holoslam-test", kernel_spec_manager=ksm)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_without_error(path, tmp_path):
    import nbformat
    from nbclient import NotebookClient

    pytest.importorskip("ipykernel")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        km=_kernel_manager(tmp_path),
        timeout=300,
        allow_errors=False,  # any cell error raises CellExecutionError
        resources={"metadata": {"path": str(tmp_path)}},  # the working folder: nothing lands in the repo
    )
    client.execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    # every notebook shows at least one picture, inline
    assert any("image/png" in o.get("data", {}) for o in outputs), f"{path.name} drew no figure"
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "Traceback" not in text
