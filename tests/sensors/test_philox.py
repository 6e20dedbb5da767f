"""The counter-based generator: numpy's Philox, the same numbers however asked."""

import numpy as np

from fahv.sensors.philox import STREAM_DYNAMIC_BIAS, STREAM_NOISE, normals, philox4x64


def test_block_function_is_numpys_philox_bit_for_bit():
    for seed, channel, step, stream in [(5, 7, 9, 0), (2**63 + 11, 3, 0, 2), (0, 0, 123456, 1)]:
        key = np.array([seed, channel], dtype=np.uint64)
        ref = np.random.Philox(key=key, counter=[step, stream, 0, 0]).random_raw(4)
        got = philox4x64((step + 1, stream, 0, 0), (seed, channel))
        np.testing.assert_array_equal(np.array(got), ref)


def test_same_seed_channel_step_same_number_however_asked():
    seeds = np.array([11, 3, 2**40 + 7], dtype=np.uint64)
    steps = np.arange(200)
    block = normals(seeds[:, None], 4, steps[None, :])  # (3, 200, 4): a batch, a block
    one_by_one = np.array([[normals(s, 4, int(k)) for k in steps] for s in seeds])
    reordered = normals(seeds[::-1, None], 4, steps[None, ::-1])[::-1, ::-1]
    tail = normals(seeds[:, None], 4, steps[None, 150:])  # a block starting later
    np.testing.assert_array_equal(block, one_by_one)
    np.testing.assert_array_equal(block, reordered)
    np.testing.assert_array_equal(block[:, 150:], tail)


def test_moments_and_independence_over_100000_draws():
    steps = np.arange(100_000)
    z = normals(1, 1, steps)[:, 0]
    # standard errors: mean 1/sqrt(N) = 0.0032, std 1/sqrt(2N) = 0.0022; 4 sigma
    assert abs(z.mean()) < 0.013
    assert abs(z.std() - 1.0) < 0.009
    others = {
        "other channel": normals(1, 2, steps)[:, 0],
        "other seed": normals(2, 1, steps)[:, 0],
        "other stream": normals(1, 1, steps, STREAM_DYNAMIC_BIAS)[:, 0],
        "second draw of the block": normals(1, 1, steps, STREAM_NOISE)[:, 1],
        "lag one step": normals(1, 1, steps + 1)[:, 0],
    }
    for what, w in others.items():
        assert abs(np.corrcoef(z, w)[0, 1]) < 0.01, what


def test_the_grid_form_draws_the_same_numbers():
    """`normals_grid` (the sensors' one call per step) gives `normals`' bits."""
    from fahv.sensors.philox import normals_grid

    seeds = np.array([0, 7, 2**63 + 5], dtype=np.uint64)
    channels = np.array([1, 4, 5], dtype=np.uint64)
    for stream in (STREAM_NOISE, STREAM_DYNAMIC_BIAS):
        grid = normals_grid(seeds, channels, 123, stream)
        assert np.array_equal(grid, normals(seeds[:, None], channels[None, :], 123, stream))
