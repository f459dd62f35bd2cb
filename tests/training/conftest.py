"""Fixtures shared by the training tests."""

from __future__ import annotations

import warnings
from collections.abc import Iterator

import pytest


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Run the test on one PyTorch thread, with warnings silenced (TorchRL's and PyTorch's
    deprecation notices). Modules whose tests train take it with
    ``pytestmark = pytest.mark.usefixtures("one_torch_thread")``."""
    import torch

    torch.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield
