"""Shared fixtures: every kernel test runs on the CPU and, where CUDA is present, on cuda:0."""

import os

import numpy as np
import pytest
import warp as wp

from wavewarp.device import init_warp

wp.config.log_level = wp.LOG_WARNING
init_warp()

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request):
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(int(os.environ.get("WAVEWARP_TEST_SEED", "20261123")))
