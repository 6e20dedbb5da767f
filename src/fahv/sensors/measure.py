"""The measurement y of B runs from their true states: y_k = sensors(x_k), noise included.

`Sensors` holds the sensor memory of B runs (delay line, lag, sample-and-hold, the
Gauss-Markov bias, faults) and returns y (B, n_y) step after step. Every random
number is a pure function of (seed of the run, channel, step) (`fahv.sensors.philox`),
so the in-process simulator, a campaign batch, a node, a rerun and a replay that
measure the same states get the same y. `noise_bound` gives the bound the white noise
of a channel stays within over a whole run with a given probability.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from statistics import NormalDist

import numpy as np

from fahv.model.vehicle import ALPHA, ETA1_DOT, ETA2_DOT, IQ, THETA, H, V
from fahv.sensors.data import (
    CHANNEL_IDS,
    CHANNEL_UNITS,
    DEFAULT_MEASURED,
    STATE_CHANNELS,
    ChannelNoise,
    SensorData,
)
from fahv.sensors.faults import SensorFaultKind
from fahv.sensors.philox import (
    STREAM_DYNAMIC_BIAS,
    STREAM_NOISE,
    STREAM_TURN_ON_BIAS,
    normals,
    normals_grid,
)

_STATE_INDEX = {"h": H, "V": V, "theta": THETA, "alpha": ALPHA}
#: Rows of `Sensors._const`.
_BIAS, _DRIFT, _MEAN, _STD, _DYN, _GM_A = range(6)


def true_outputs(
    x: np.ndarray, data: SensorData, measured: Sequence[str] = DEFAULT_MEASURED
) -> np.ndarray:
    """Noise-free outputs of the channels: the states, and the gyro's q with the modes.

    Parameters
    ----------
    x : (B, n) ndarray, n >= 9
        True states (CM order; an ECM state's extra notch states are ignored)
        [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s, ...].
    data : SensorData
        Mode slopes phi_1, phi_2 at the gyro.
    measured : sequence of str
        Channels, in output order.

    Returns
    -------
    (B, n_y) ndarray
        q_gyro = q + phi_1 eta_1_dot + phi_2 eta_2_dot [rad/s] for `q`, the state for
        the others, in the units of `CHANNEL_UNITS`.
    """
    x = np.atleast_2d(np.asarray(x, dtype=float))
    cols = []
    for name in measured:
        if name == "q":
            cols.append(x[:, IQ] + data.phi_1 * x[:, ETA1_DOT] + data.phi_2 * x[:, ETA2_DOT])
        else:
            cols.append(x[:, _STATE_INDEX[name]])
    return np.stack(cols, axis=1)


def output_matrix(measured: Sequence[str], data: SensorData) -> np.ndarray:
    """C (n_y, 9) of the noise-free outputs y = C x of the measured channels.

    The linear form of `true_outputs` (the same channels, the same mode slopes), for
    an estimator's output equation.

    Parameters
    ----------
    measured : sequence of str
        Channels in output order (`fahv.sensors.data.CHANNELS`).
    data : SensorData
        The mode slopes phi_1, phi_2 at the gyro.

    Returns
    -------
    (n_y, 9) ndarray
        Row of a state channel: its unit vector; row of `q`: the gyro,
        q + phi_1 eta_1_dot + phi_2 eta_2_dot.

    Raises
    ------
    KeyError
        On an unknown channel.

    Examples
    --------
    >>> from fahv.sensors.data import load_sensors
    >>> output_matrix(["h", "theta"], load_sensors())[:, :4]
    array([[1., 0., 0., 0.],
           [0., 0., 0., 1.]])
    """
    C = np.zeros((len(measured), 9))
    for r, name in enumerate(measured):
        if name == "q":
            C[r, IQ], C[r, ETA1_DOT], C[r, ETA2_DOT] = 1.0, data.phi_1, data.phi_2
        else:
            C[r, _STATE_INDEX[name]] = 1.0
    return C


def white_noise(seeds, channel: str, steps, noise: ChannelNoise) -> np.ndarray:
    """White noise mean + stddev z of a channel for runs `seeds` at steps `steps`.

    Parameters
    ----------
    seeds, steps : int or array_like of int
        Run seeds and step indexes, broadcast together.
    channel : str
        Channel name (its id keys the generator).
    noise : ChannelNoise
        Mean and standard deviation [unit of the channel].

    Returns
    -------
    ndarray
        Of the broadcast shape, in the channel's unit.
    """
    z = normals(seeds, CHANNEL_IDS[channel], steps, STREAM_NOISE)[..., 0]
    return noise.mean + noise.stddev * z


def noise_bound(stddev: float, n_steps: int, p: float) -> float:
    """Bound b with P(|n_k| <= b for all N steps) >= p, for white Gaussian n_k.

    Union over the steps: b = stddev Phi^-1(1 - (1 - p) / (2 N)).

    Parameters
    ----------
    stddev : float
        Standard deviation of the noise [any unit].
    n_steps : int
        Number N of independent samples in the run.
    p : float
        Probability, 0 < p < 1.

    Returns
    -------
    float
        The bound, in the unit of `stddev`.

    Examples
    --------
    >>> round(noise_bound(1.0, 15000, 0.999), 3)
    5.4
    """
    return stddev * -NormalDist().inv_cdf((1.0 - p) / (2.0 * n_steps))


#: Columns of a run's sensor dispersion (`Sensors`' `dispersion`): factor on every
#: channel's white-noise stddev, factor on its turn-on bias stddev, shift of its turn-on
#: bias mean [its white-noise stddevs].
SENSOR_DISPERSION = ("stddev", "bias_stddev", "bias_mean")


def sensor_dispersion(dispersion, n_runs: int) -> np.ndarray:
    """The (B, 3) sensor dispersion of `n_runs` runs (`SENSOR_DISPERSION`); None: none.

    Raises
    ------
    ValueError
        If it is not (B, 3), not finite, or a factor is negative.
    """
    if dispersion is None:
        out = np.zeros((n_runs, 3))
        out[:, :2] = 1.0
        return out
    d = np.asarray(dispersion, dtype=float)
    if d.shape != (n_runs, 3) or not np.all(np.isfinite(d)) or (d[:, :2] < 0.0).any():
        raise ValueError(f"sensor dispersion {d.tolist()}: expected ({n_runs}, 3) finite "
                         f"values {SENSOR_DISPERSION}, the factors >= 0")  # fmt: skip
    return d


class Sensors:
    """The sensors of B runs: y_k (B, n_y) from the true state x_k, step by step.

    Per channel and step k: the true output of step k - delay, the lag C_1/(s + C_1),
    a new sample every `period` steps (held between), plus constant, turn-on, drift
    and Gauss-Markov biases and white noise, the channel's fault, then quantisation
    to `precision`.

    Parameters
    ----------
    data : SensorData
        Noise models and mode slopes (`fahv.sensors.data.load_sensors`).
    seeds : (B,) array_like of int
        Seed of each run (keys its numbers).
    Ts : float
        Step [s].
    measured : sequence of str
        Channels, in output order (default h, V, theta, q).
    faults : sequence of SensorFaultKind or None, optional
        One-run fault of each run (None: healthy), length B.
    dispersion : (B, 3) array_like, optional
        Per run, every channel's white-noise stddev and turn-on bias stddev scaled by
        the first two columns, its turn-on bias mean moved by the third times its
        stddev (`SENSOR_DISPERSION`; a campaign's sensor dispersion). By default
        (1, 1, 0): the vehicle file's sensors, bit for bit.

    Raises
    ------
    ValueError
        If `faults` does not have B entries, a fault's channel is not measured, or
        `dispersion` is not (B, 3) with finite, non-negative factors.
    """

    def __init__(self, data, seeds, Ts: float, measured=DEFAULT_MEASURED, faults=None,
                 dispersion=None) -> None:  # fmt: skip
        self.data, self.Ts = data, float(Ts)
        self.seeds = np.atleast_1d(np.asarray(seeds, dtype=np.uint64))
        self.names = tuple(measured)
        #: Unit of each output.
        self.units = tuple(CHANNEL_UNITS[c] for c in self.names)
        self.noise = [data.channels[c] for c in self.names]
        B, n_y = self.seeds.size, len(self.names)
        faults = [None] * B if faults is None else list(faults)
        if len(faults) != B:
            raise ValueError(f"faults: {len(faults)} entries for {B} runs")
        self.groups: list[tuple[int, np.ndarray, SensorFaultKind]] = []
        by_kind: dict[tuple, list] = {}
        for run, f in enumerate(faults):
            if f is not None:
                if f.channel not in self.names:
                    raise ValueError(f"sensor fault on {f.channel!r}, not measured {self.names}")
                by_kind.setdefault((type(f), f.channel), []).append((run, f))
        for (cls, channel), fl in by_kind.items():
            runs = np.array([r for r, _ in fl])
            self.groups.append((self.names.index(channel), runs, cls.stack([f for _, f in fl])))
        self.k = -1
        self._line = np.zeros((max(n.delay for n in self.noise) + 1, B, n_y))
        self._lagged = np.zeros((B, n_y))
        self._sample = np.zeros((B, n_y))
        self._gm = np.zeros((B, n_y))
        self.y = np.zeros((B, n_y))
        self._ids = np.array([CHANNEL_IDS[c] for c in self.names], dtype=np.uint64)
        self._period = np.array([n.period for n in self.noise])
        #: Per channel (columns), the rows _BIAS, _DRIFT, _MEAN, _STD, _DYN, _GM_A: bias,
        #: drift rate, white noise mean and stddev, Gauss-Markov stddev and its factor
        #: exp(-period Ts / correlation time) per sample (0 without that bias).
        self._const = np.array([
            (n.bias, n.drift_rate, n.mean, n.stddev, n.dynamic_bias_stddev,
             math.exp(-n.period * self.Ts / n.dynamic_bias_correlation_time)
             if n.dynamic_bias_stddev > 0.0 else 0.0)
            for n in self.noise
        ]).T.reshape(6, n_y)  # fmt: skip
        #: Per channel, the discrete lag's gain 1 - exp(-C_1 Ts); channels without a lag.
        self._lag_gain = np.array([-math.expm1(-n.lag * self.Ts) for n in self.noise])
        self._lagged_off = np.array([n.lag == 0.0 for n in self.noise])
        disp = sensor_dispersion(dispersion, B)
        #: White-noise stddev of each run and channel (B, n_y).
        self._std = self._const[_STD] * disp[:, 0:1]
        #: Turn-on bias of each run and channel (B, n_y), drawn at step 0.
        self.turn_on = np.zeros((B, n_y))
        # the draws of every channel in the one compiled call a step uses (compiled here,
        # at the sensors' construction, not in a run's first step)
        z_all = normals_grid(self.seeds, self._ids, 0, STREAM_TURN_ON_BIAS)[..., 0]
        for j, n in enumerate(self.noise):
            z = z_all[:, j]
            mean = n.bias_mean + disp[:, 2] * n.stddev
            self.turn_on[:, j] = mean + (n.bias_stddev * disp[:, 1]) * z

    def _delayed(self, z: np.ndarray) -> np.ndarray:
        """True outputs of step k - delay per channel (the first ones before step delay)."""
        if self._line.shape[0] == 1:  # no channel delays
            return z
        if self.k == 0:
            self._line[:] = z
        self._line = np.roll(self._line, 1, axis=0)
        self._line[0] = z
        return np.stack([self._line[n.delay, :, j] for j, n in enumerate(self.noise)], axis=1)

    def _new_samples(self, due: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The samples of channels `due` (m,) at step k: values z (B, m), biases, noise.

        One draw per stream for all of them (the numbers of `white_noise`, channel by
        channel: a draw depends on seed, channel and step only).
        """
        k, ids, c = self.k, self._ids[due], self._const[:, due]
        dyn = c[_DYN]
        if (dyn > 0.0).any():
            w = normals_grid(self.seeds, ids, k, STREAM_DYNAMIC_BIAS)[..., 0]
            if k == 0:
                self._gm[:, due] = dyn * w
            else:
                a = c[_GM_A]
                self._gm[:, due] = a * self._gm[:, due] + dyn * np.sqrt(1.0 - a * a) * w
        bias = c[_BIAS] + self.turn_on[:, due] + c[_DRIFT] * k * self.Ts + self._gm[:, due]
        return z + bias + (c[_MEAN] + self._std[:, due] * normals_grid(self.seeds, ids, k)[..., 0])

    def measure(self, k: int, x: np.ndarray) -> np.ndarray:
        """The measurement of step k from the true states x_k of the B runs.

        Parameters
        ----------
        k : int
            Step; 0 restarts the sensors, otherwise the step after the previous call.
        x : (B, n) ndarray, n >= 9
            True states at step k (CM or ECM order).

        Returns
        -------
        (B, n_y) ndarray
            y_k in the units `units`, channels `names`.

        Raises
        ------
        ValueError
            If k is neither 0 nor the step after the previous call.
        """
        if k not in (0, self.k + 1):
            raise ValueError(f"measure: step {k} after step {self.k} (steps go 0, 1, 2, ...)")
        self.k = k
        if k == 0:
            for _, _, fault in self.groups:
                fault.held[:] = np.nan
        z = self._delayed(true_outputs(np.reshape(x, (self.seeds.size, -1)), self.data, self.names))
        last = self.y.copy()
        if k == 0:
            self._lagged[:] = z
        else:
            lagged = self._lagged + self._lag_gain * (z - self._lagged)
            self._lagged = np.where(self._lagged_off, z, lagged)
        due = np.flatnonzero(k % self._period == 0)
        if due.size:
            self._sample[:, due] = self._new_samples(due, self._lagged[:, due])
        y = self._sample.copy()
        if k == 0:
            last = y.copy()
        t = k * self.Ts
        for j, runs, fault in self.groups:
            act = fault.active(t)
            if act.any():
                lanes = np.flatnonzero(act)
                rows = runs[lanes]
                y[rows, j] = fault.apply(y[rows, j], last[rows, j], t, lanes)
        for j, n in enumerate(self.noise):
            if n.precision > 0.0:
                y[:, j] = n.precision * np.round(y[:, j] / n.precision)
        self.y = y
        return y.copy()


class ExactState:
    """The full-state sensor of the paper's loop: y_k = x_k, every state, no error.

    The measurement of `measured` = `state` (`fahv.sensors.data.EXACT_STATE`): with
    the estimator `none` the controller then reads the exact state, flexible states
    included, as eq. (36) assumes.

    Parameters
    ----------
    n_runs : int
        Runs B.
    """

    names: tuple[str, ...] = STATE_CHANNELS

    def __init__(self, n_runs: int) -> None:
        self.n_runs = int(n_runs)

    def measure(self, k: int, x: np.ndarray) -> np.ndarray:
        """y_k (B, 9): a copy of the first nine columns of x (B, >= 9) [plant units]."""
        return np.array(x[:, :9], dtype=float)


def measure_history(data: SensorData, seeds, Ts: float, x: np.ndarray, measured=DEFAULT_MEASURED,
                    faults=None, dispersion=None) -> np.ndarray:  # fmt: skip
    """The measurements of whole runs from their state histories (a run's record).

    The same numbers as `Sensors.measure` called step by step during the runs: y is a
    function of the states and the seeds only.

    Parameters
    ----------
    data : SensorData
        Noise models and mode slopes.
    seeds : (B,) array_like of int
        Seed of each run.
    Ts : float
        Step [s].
    x : (N, B, n) or (N, n) ndarray, n >= 9
        True states of N steps (a single run may drop the B axis).
    measured : sequence of str
        Channels, in output order.
    faults : sequence of SensorFaultKind or None, optional
        One-run fault of each run (None: healthy).
    dispersion : (B, 3) array_like, optional
        Each run's sensor dispersion (`Sensors`); None: none.

    Returns
    -------
    (N, B, n_y) ndarray, or (N, n_y) for an (N, n) history
    """
    x = np.asarray(x, dtype=float)
    single = x.ndim == 2
    xs = x[:, None, :] if single else x
    sensors = Sensors(data, seeds, Ts, measured, faults, dispersion)
    y = np.stack([sensors.measure(k, xs[k]) for k in range(xs.shape[0])])
    return y[:, 0, :] if single else y
