"""The ablation notebooks run top to bottom (at their CPU budget on a CPU)."""

import os

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = os.path.join(os.path.dirname(__file__), "..", "..", "experiments", "notebooks")


@pytest.mark.parametrize("name", ["ablation_alpha.ipynb", "ablation_eps.ipynb"])
def test_notebook_runs(name):
    nb = nbformat.read(os.path.join(NOTEBOOKS, name), as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3",
                   resources={"metadata": {"path": NOTEBOOKS}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "success" in text and "reward gap" in text  # the summary printed at the end
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the plot
