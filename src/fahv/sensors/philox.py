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

The block function is written here in numpy over arrays of any shape, so a batch of
B runs and N steps costs one vectorised evaluation; a test checks it bit for bit
against numpy's own generator.
"""

from __future__ import annotations

import numpy as np

_M0 = np.uint64(0xD2E7470EE14C6C93)
_M1 = np.uint64(0xCA5A826395121157)
_W0 = np.uint64(0x9E3779B97F4A7C15)
_W1 = np.uint64(0xBB67AE8584CAA73B)
_LO32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_ROUNDS = 10

#: Streams of one (seed, channel): white measurement noise, the Gauss-Markov bias's
#: driving noise, the run's turn-on bias (drawn at step 0).
STREAM_NOISE, STREAM_DYNAMIC_BIAS, STREAM_TURN_ON_BIAS = 0, 1, 2


def _mulhilo(a: np.ndarray, b: np.uint64) -> tuple[np.ndarray, np.ndarray]:
    """High and low 64-bit words of the 128-bit product a b (uint64 arrays)."""
    a0, a1 = a & _LO32, a >> _S32
    b0, b1 = b & _LO32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _LO32) + (p10 & _LO32)
    hi = p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32)
    return hi, a * b


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
    with np.errstate(over="ignore"):
        c = [np.asarray(w, dtype=np.uint64) for w in counter]
        k0, k1 = (np.asarray(w, dtype=np.uint64) for w in key)
        for r in range(_ROUNDS):
            if r:
                k0, k1 = k0 + _W0, k1 + _W1
            hi0, lo0 = _mulhilo(c[0], _M0)
            hi1, lo1 = _mulhilo(c[2], _M1)
            c = [hi1 ^ c[1] ^ k0, lo1, hi0 ^ c[3] ^ k1, lo0]
    return tuple(c)


def _uniform_open(w: np.ndarray) -> np.ndarray:
    """(w // 2^11 + 1) 2^-53, in (0, 1]."""
    return ((w >> np.uint64(11)).astype(np.float64) + 1.0) * 2.0**-53


def _uniform(w: np.ndarray) -> np.ndarray:
    """(w // 2^11) 2^-53, in [0, 1)."""
    return (w >> np.uint64(11)).astype(np.float64) * 2.0**-53


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
    with np.errstate(over="ignore"):
        ctr = (
            step + np.uint64(1),
            np.full_like(step, stream),
            np.zeros_like(step),
            np.zeros_like(step),
        )
    w = philox4x64(ctr, (seed, channel))
    out = np.empty(step.shape + (4,))
    for i in (0, 2):
        r = np.sqrt(-2.0 * np.log(_uniform_open(w[i])))
        phase = 2.0 * np.pi * _uniform(w[i + 1])
        out[..., i] = r * np.cos(phase)
        out[..., i + 1] = r * np.sin(phase)
    return out
