"""The torchvision check of the deepinv integration (splitcam.integrations._torchvision): a
torchvision whose compiled operators do not load beside this torch is named in one line with
the command that installs the matching one; no operators are declared on its behalf."""

from __future__ import annotations

import importlib.machinery

import torch

from splitcam.integrations._torchvision import torchvision_mismatch


def _nms_declared() -> bool:
    try:
        torch.ops.torchvision.nms  # noqa: B018
    except (AttributeError, RuntimeError):
        return False
    return True


def test_operators_that_do_not_load_are_named_with_the_fix(tmp_path):
    declared_before = _nms_declared()
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    (tmp_path / f"_C_stable{suffix}").write_bytes(b"not a shared library")
    line = torchvision_mismatch(tmp_path)
    assert line is not None and "\n" not in line
    assert f"beside torch {torch.__version__}" in line
    minor = int(torch.__version__.split(".")[1])
    release = torch.__version__.split("+")[0]
    # The pair again, together, from one index: torchvision alone was "already satisfied".
    assert (
        f"pip install --isolated --force-reinstall 'torch=={release}' "
        f"'torchvision==0.{minor + 15}.*'" in line
    )
    if "+" in torch.__version__:
        assert line.endswith(f"download.pytorch.org/whl/{torch.__version__.split('+')[1]})")
    # Nothing was declared on torchvision's behalf (the old stand-in defined nms); where a working
    # torchvision was imported before, its own nms is there before and after.
    assert _nms_declared() == declared_before


def test_a_folder_without_compiled_operators_is_not_a_mismatch(tmp_path):
    assert torchvision_mismatch(tmp_path) is None
