"""Counter-based Gaussian draws: numpy's Philox evaluated for any (seed, channel, step).

The number drawn for a run's seed, a sensor channel and a step is a pure function of
those three integers (and a stream number), never of the order, block or batch in
which a consumer asks for it. The construction is numpy's `Philox` bit generator
(Philox4x64-10, Salmon et al. 2011):

- key = (seed, channel id), two 64-bit words;
- counter = (step, stream, 0, 0): the four 64-bit words that
  `numpy.random.Philox(key=(seed, channel), counter=(step, stream, 0, 0)).random_raw(4)`
  returns (numpy encrypts the counter incremented by one);
- two standard normal draws from those four words by Box-Muller, with
  u_1 = (w_0 // 2^11 + 1) 2^-53 in (0, 1] and u_2 = (w_1 // 2^11) 2^-53:
  z_0 = sqrt(-2 ln u_1) cos(2 pi u_2) and z_1 = sqrt(-2 ln u_1) sin(2 pi u_2);
  words w_2, w_3 give the next two the same way.

The block function and Box-Muller are compiled (numba, one loop over the draws asked
for), so one draw costs microseconds and a batch of B runs and N steps one call; a test
checks the block function bit for bit against numpy's own generator. Every consumer
calls these same compiled functions, so the node, the simulator, a batch and a replay
get the same bits (libm's log, cos and sin, not numpy's vectorised ones).
"""

from __future__ import annotations

import math

import numba
import numpy as np

_M0 = np.uint64(0xD2E7470EE14C6C93)
_M1 = np.uint64(0xCA5A826395121157)
_W0 = np.uint64(0x9E3779B97F4A7C15)
_W1 = np.uint64(0xBB67AE8584CAA73B)
_LO32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_S11 = np.uint64(11)
_ONE = np.uint64(1)
_ROUNDS = 10

#: Streams of one (seed, channel): white measurement noise, the Gauss-Markov bias's
#: driving noise, the run's turn-on bias (drawn at step 0).
STREAM_NOISE, STREAM_DYNAMIC_BIAS, STREAM_TURN_ON_BIAS = 0, 1, 2


@numba.njit(cache=True, inline="always")
def _mulhilo(a, b):
    """High and low 64-bit words of the 128-bit product a b (uint64)."""
    a0, a1 = a & _LO32, a >> _S32
    b0, b1 = b & _LO32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _LO32) + (p10 & _LO32)
    hi = p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32)
    return hi, a * b


@numba.njit(cache=True, inline="always")
def _block(x0, x1, x2, x3, y0, y1):
    """Philox4x64-10 of one counter (x0, x1, x2, x3) under the key (y0, y1): 4 words."""
    for r in range(_ROUNDS):
        if r:
            y0 += _W0
            y1 += _W1
        hi0, lo0 = _mulhilo(x0, _M0)
        hi1, lo1 = _mulhilo(x2, _M1)
        x0, x1, x2, x3 = hi1 ^ x1 ^ y0, lo1, hi0 ^ x3 ^ y1, lo0
    return x0, x1, x2, x3


@numba.njit(cache=True)
def _blocks(c0, c1, c2, c3, k0, k1, out):
    """Philox4x64-10 of flat uint64 arrays (n,) into out (n, 4), element by element.

    Compiled (numba): numpy's per-call overhead made the vectorised form cost 0.3 ms
    for the one draw of a channel and step.
    """
    for i in range(c0.size):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _block(c0[i], c1[i], c2[i], c3[i],
                                                            k0[i], k1[i])  # fmt: skip


@numba.njit(cache=True, inline="always")
def _box_muller_row(w, out):
    """Four N(0, 1) draws from four words w (4,) into out (4,) (see the module notes)."""
    for j in (0, 2):
        u1 = (float(w[j] >> _S11) + 1.0) * 2.0**-53
        u2 = float(w[j + 1] >> _S11) * 2.0**-53
        r = math.sqrt(-2.0 * math.log(u1))
        out[j] = r * math.cos(2.0 * math.pi * u2)
        out[j + 1] = r * math.sin(2.0 * math.pi * u2)


@numba.njit(cache=True)
def _box_muller(w, out):
    """Four N(0, 1) draws per row of words w (n, 4) into out (n, 4) (see the module notes)."""
    for i in range(w.shape[0]):
        _box_muller_row(w[i], out[i])


@numba.njit(cache=True)
def _grid(seeds, channels, c0, c1, out):
    """The draws of every (seed, channel) at counter (c0, c1, 0, 0) into out (B, m, 4)."""
    w = np.empty(4, dtype=np.uint64)
    zero = np.uint64(0)
    for b in range(seeds.size):
        for c in range(channels.size):
            w[0], w[1], w[2], w[3] = _block(c0, c1, zero, zero, seeds[b], channels[c])
            _box_muller_row(w, out[b, c])


def philox4x64(counter: tuple, key: tuple) -> tuple[np.ndarray, ...]:
    """The Philox4x64-10 block function, elementwise over broadcast uint64 arrays.

    Parameters
    ----------
    counter : tuple of 4 array_like of uint64
        Counter words (c_0, c_1, c_2, c_3), broadcast together with the key.
    key : tuple of 2 array_like of uint64
        Key words (k_0, k_1).

    Returns
    -------
    tuple of 4 ndarray of uint64
        The four output words, of the broadcast shape.
    """
    words = np.broadcast_arrays(*(np.asarray(w, dtype=np.uint64) for w in (*counter, *key)))
    shape = words[0].shape
    flat = [np.array(w).ravel() for w in words]  # copies: broadcast views are read-only
    out = np.empty((flat[0].size, 4), dtype=np.uint64)
    _blocks(*flat, out)
    return tuple(out[:, i].reshape(shape) for i in range(4))


def normals(seed, channel, step, stream: int = STREAM_NOISE) -> np.ndarray:
    """Standard normal draws for (seed, channel, step): four per counter.

    Parameters
    ----------
    seed : int or array_like of int
        Run seed(s), 0 <= seed < 2^64; broadcast with `channel` and `step`.
    channel : int or array_like of int
        Channel id(s) (`fahv.sensors.model.CHANNEL_IDS`).
    step : int or array_like of int
        Step index(es) k >= 0.
    stream : int
        Which stream of the channel (`STREAM_NOISE`, ...).

    Returns
    -------
    (..., 4) ndarray
        Four independent N(0, 1) draws per element of the broadcast shape of
        (seed, channel, step); the same numbers for the same integers, however asked.

    Examples
    --------
    >>> a = normals(7, 1, np.arange(5))[:, 0]
    >>> b = np.array([normals(7, 1, k)[0] for k in range(5)])
    >>> bool(np.array_equal(a, b))
    True
    """
    seed, channel, step = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.uint64) for v in (seed, channel, step))
    )
    shape = step.shape
    with np.errstate(over="ignore"):
        c0 = np.array(step).ravel() + _ONE
    c1 = np.full(c0.size, stream, dtype=np.uint64)
    zero = np.zeros(c0.size, dtype=np.uint64)
    w = np.empty((c0.size, 4), dtype=np.uint64)
    _blocks(c0, c1, zero, zero, np.array(seed).ravel(), np.array(channel).ravel(), w)
    out = np.empty((c0.size, 4))
    _box_muller(w, out)
    return out.reshape(shape + (4,))


def normals_grid(seeds: np.ndarray, channels: np.ndarray, step: int,
                 stream: int = STREAM_NOISE) -> np.ndarray:  # fmt: skip
    """`normals` of every (seed, channel) pair at one step, with little per-call work.

    The numbers of `normals(seeds[:, None], channels[None, :], step, stream)`, bit for
    bit (the same compiled kernels); the sensors call it once per step.

    Parameters
    ----------
    seeds : (B,) ndarray of uint64
        Run seeds.
    channels : (m,) ndarray of uint64
        Channel ids.
    step : int
        Step index k >= 0.
    stream : int
        Which stream of the channels.

    Returns
    -------
    (B, m, 4) ndarray
    """
    out = np.empty((seeds.size, channels.size, 4))
    _grid(np.ascontiguousarray(seeds, dtype=np.uint64),
          np.ascontiguousarray(channels, dtype=np.uint64), np.uint64(step + 1),
          np.uint64(stream), out)  # fmt: skip
    return out
