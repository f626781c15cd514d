#!/usr/bin/python3
"""A bank of randomised scenarios with known truth for the estimator and the fault detector.

What it does
------------
Each scenario is a plant of 1 to 4 resonant modes, an experiment (open or closed
loop, rich or poor excitation, white output noise) and the config a user would
write for it from a nominal model and default settings. For scenario <id> it
writes, under DIR/<id>/:

    config.yaml   plant: (the truth, with the fault's trajectory), simulation:,
                  model: (the nominal model: wn +-3 %, zeta +-20 %, gain +-10 %),
                  controller: (closed loop), estimator:, daemon: (publish
                  period), faults:
    meta.json     the truth, the fault (kind, mode, size, timing), the memory,
                  lambda, the detector's thresholds, and the identifiability
                  figures (Cramer-Rao bounds over one memory, Fisher matrix rank)
    record.csv    t,r,u,y from `modalwatch simulate`
    truth.csv     the true modal parameters per sample

How to run it
-------------
    /usr/bin/python3 scripts/study/scenario_bank.py generate --out /tmp/bank \\
        --count 12 --seed 1 --scale small [--healthy-only|--faults-only|--skip-healthy|--skip-faults] \\
        [--modalwatch build/modalwatch] [--no-simulate]
(--faults-only draws a bank of fault records; --skip-healthy draws the same
bank as without it and writes only its fault records, to re-run those of a
full bank in a fraction of its time; --skip-faults writes only its healthy
records.)
then `scripts/study/scenario_eval.py /tmp/bank`. Needs numpy and scipy.

Rules (the same for every record; nothing is tuned per record)
-------------------------------------------------------------
Plant: K = 1..4 modes; wn T log-uniform in [0.005, 1.2], neighbours at least
1.4x apart; zeta log-uniform in [0.005, 0.3]; DC gains log-uniform within 20x
of each other; sample rate log-uniform in [20 Hz, 10 kHz], wn = (wn T) / T.

Memory (the estimator's default rule): N = 50 periods of the slowest mode,
in samples, N = round(50 * 2 pi / (wn_min T)); lambda = 1 - 1/N, written as
every submodel's `forgetting`. Durations below are in memories M = N T s.

Estimator: defaults, apart from lambda and a warm-up of 1 M with
fit_on_warmup true.

Faults: the thresholds of config/flexible-beam-drift.yaml (wn 3 % and 4 sigma,
zeta 50 % and 6 sigma, gain 10 % and 4 sigma); the baseline is learned over
3 M after the warm-up; hold = clear_time = 1 M. The estimate of a step moves
with the time constant of the memory, so a 2x-threshold step crosses the
threshold about 0.7 M after the change: a hold of 1 M then flags it within
about 2 M, and asks a noise excursion to outlast the estimate's correlation
time (about one memory) before it counts. The detector's memory is the
estimator's (Ts / (1 - lambda) = 1 M, derived by modalwatch); it updates every
M / 20 (daemon.publish_period, at least one sample) and is designed for a mean
of 1000 h between false alarms per mode (faults.false_alarm_interval).

Records: healthy 100 M (small: 20 M); a fault record has one change on one
mode, starting at 10-15 M (small: 6-8 M) and lasting at least 8 M (small: 5 M)
after the change is complete. Kinds: stiffness loss 3-20 % (wn x sqrt(1-loss),
gain x 1/(1-loss)) half of the faults, damping x0.5 or x2 a quarter, gain +-20 %
a quarter; each a step (one sample) or a ramp over 0.2-5 M (small: 0.2-2 M).

Excitation (input u in open loop, setpoint r in closed loop), about two thirds
rich: a multisine over [0.5 f_1, 1.5 f_K] when that band needs at most 150
lines 0.25 f_1 apart, else a PRBS clocked for f_K; a third poor: a symmetric
square wave below the slowest mode, or one sine near each mode plus a slow one
(2K + 2 real equations for 3K parameters: for K >= 3 a direction stays open).

Controller (closed loop): a PI, C(q) = kp + ki T q / (q - 1), searched on the
ZOH-discretised true plant: the highest integral crossover wc = ki g_dc (from
wn_1 / 2 down) and then the largest kp such that the closed-loop poles (the
eigenvalues of the loop's state matrix) lie inside the unit circle with margin,
i.e. |z| <= 1 - (1 - r_max) / 2 with r_max the plant's largest pole radius, at
gains 1, 1.25, 1.5, 1.75 and 2 times (kp, ki), and for the faulted plant too.

Noise and identifiability: an SNR drawn in [20, 60] dB sets the noise variance
(output power from the line spectrum of the steady-state noise-free output).
The Fisher information of the modal parameters (ln wn, ln zeta, ln gain of every
mode) over one memory of N samples is N / sigma^2 * R, R the per-sample average of
psi psi^T, psi = d y_hat / d ln theta driven by the input's lines (closed loop:
by the r-driven part of u, u_r = C / (1 + C G) r, which the instrument uses);
the bound is its pseudo-inverse (the directions the data determine; rank and
condition are recorded). A scenario is kept when every mode has std(wn) <= 0.25 %
and std(zeta) <= 4 %; otherwise the SNR and excitation are re-drawn, then the
plant. (An exponentially forgetting estimator averages about 2N samples, so its
steady-state std is about 1/sqrt(2) of these bounds.)
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import scipy.linalg

MEMORY_PERIODS = 50
WARMUP_MEMORIES = 1.0
LEARN_MEMORIES = 3.0
HOLD_MEMORIES = 1.0
PUBLISH_MEMORIES = 0.05  # detector updates every 1/20 memory (at least every sample)
FALSE_ALARM_INTERVAL_H = 1000.0  # the detector's default, written out
THRESHOLDS = {"wn": {"sigma": 4.0, "relative": 0.03},
              "zeta": {"sigma": 6.0, "relative": 0.5},
              "gain": {"sigma": 4.0, "relative": 0.1}}
CRB_WN_MAX = 0.0025
CRB_ZETA_MAX = 0.04
SCALES = {  # durations in memories
    "full": {"healthy": 100.0, "change": (10.0, 15.0), "after": (8.0, 10.0), "ramp": (0.2, 5.0)},
    "small": {"healthy": 20.0, "change": (6.0, 8.0), "after": (5.0, 6.0), "ramp": (0.2, 2.0)},
}
MAX_MULTISINE_LINES = 150
QUANTITIES = ("wn", "zeta", "gain")


def log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


# ---------------------------------------------------------------- plant and its ZOH model

def mode_zoh(wn, zeta, gain, T):
    """Phi, Gamma, C of gain wn^2 / (s^2 + 2 zeta wn s + wn^2) held by a ZOH."""
    A = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
    M = np.zeros((3, 3))
    M[:2, :2] = A * T
    M[1, 2] = gain * wn * wn * T
    E = scipy.linalg.expm(M)
    return E[:2, :2], E[:2, 2], np.array([1.0, 0.0])


def mode_response(wn, zeta, gain, T, w):
    """The ZOH mode at z = exp(j w), w in rad/sample (vectorised over w)."""
    Phi, Gam, _ = mode_zoh(wn, zeta, gain, T)
    z = np.exp(1j * np.asarray(w, dtype=float))
    a, b, c, d = Phi[0, 0], Phi[0, 1], Phi[1, 0], Phi[1, 1]
    det = (z - a) * (z - d) - b * c
    return ((z - d) * Gam[0] + b * Gam[1]) / det  # first row of (zI - Phi)^-1 Gamma


def plant_response(modes, T, w):
    return sum(mode_response(m["wn"], m["zeta"], m["gain"], T, w) for m in modes)


def plant_state_space(modes, T):
    n = 2 * len(modes)
    Phi, Gam, C = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    for i, m in enumerate(modes):
        P, G, c = mode_zoh(m["wn"], m["zeta"], m["gain"], T)
        Phi[2 * i:2 * i + 2, 2 * i:2 * i + 2] = P
        Gam[2 * i:2 * i + 2] = G
        C[2 * i:2 * i + 2] = c
    return Phi, Gam, C


def draw_plant(rng):
    K = int(rng.integers(1, 5))
    while True:
        wnT = np.sort([log_uniform(rng, 0.005, 1.2) for _ in range(K)])
        if K == 1 or np.all(wnT[1:] / wnT[:-1] >= 1.4):
            break
    fs = log_uniform(rng, 20.0, 10000.0)
    gains = np.array([log_uniform(rng, 1.0, 20.0) for _ in range(K)])
    gains *= log_uniform(rng, 1e-6, 1e2) / gains.min()  # overall scale: units are arbitrary
    modes = [{"name": f"mode{i + 1}", "wn": float(wnT[i] * fs), "zeta": log_uniform(rng, 0.005, 0.3),
              "gain": float(gains[i])} for i in range(K)]
    return fs, modes


# ---------------------------------------------------------------- controller

def pi_controller(kp, ki, T):
    """C(q) = kp + ki T q / (q - 1): numerator, denominator in descending powers of q."""
    return [kp + ki * T, -kp], [1.0, -1.0]


def closed_loop_radius(modes, T, kp, ki):
    Phi, Gam, C = plant_state_space(modes, T)
    n = len(Phi)
    d = kp + ki * T  # u = ki T xc + (kp + ki T) e, xc+ = xc + e, e = r - C x
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = Phi - d * np.outer(Gam, C)
    A[:n, n] = Gam * ki * T
    A[n, :n] = -C
    A[n, n] = 1.0
    return np.abs(np.linalg.eigvals(A)).max()


def plant_radius(modes, T):
    return max(math.exp(-m["zeta"] * m["wn"] * T) for m in modes)


def stable_with_margin(plants, T, kp, ki):
    for modes in plants:
        limit = 1.0 - 0.5 * (1.0 - plant_radius(modes, T))
        for f in (1.0, 1.25, 1.5, 1.75, 2.0):
            if not closed_loop_radius(modes, T, f * kp, f * ki) <= limit:
                return False
    return True


def design_controller(plants, T):
    """Highest integral crossover, then largest proportional gain, stable with margin."""
    modes = plants[0]
    g_dc = sum(m["gain"] for m in modes)
    wn1 = modes[0]["wn"]
    wc = 0.5 * wn1
    while wc > 1e-4 * wn1:
        ki = wc / g_dc
        if stable_with_margin(plants, T, 0.0, ki):
            best = 0.0
            for ratio in (3.0, 1.0, 0.3, 0.1, 0.03):
                kp = ratio / g_dc
                if stable_with_margin(plants, T, kp, ki):
                    best = kp
                    break
            return {"kp": best, "ki": ki, "crossover_rad_s": wc,
                    "radius": float(closed_loop_radius(modes, T, best, ki))}
        wc *= 0.7
    return None


# ---------------------------------------------------------------- excitation and its lines

def draw_excitation(rng, modes, fs, poor):
    f = [m["wn"] / (2 * math.pi) for m in modes]
    if poor:
        if rng.uniform() < 0.5:
            period = 2 * max(1, int(round(fs / (f[0] * rng.uniform(1.5, 4.0)) / 2)))  # even: symmetric
            return {"type": "square", "frequency_hz": fs / period, "amplitude": 1.0, "period_samples": period}
        w = [m["wn"] * (1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.02, 0.15)) for m in modes]
        w = [modes[0]["wn"] * rng.uniform(0.05, 0.3)] + w
        return {"type": "sum_of_sines", "amplitudes": [1.0] * len(w), "frequencies_rad_s": w}
    f_lo, f_hi = 0.5 * f[0], min(1.5 * f[-1], 0.45 * fs)
    spacing = 0.25 * f[0]
    if (f_hi - f_lo) / spacing <= MAX_MULTISINE_LINES:
        return {"type": "multisine", "f_min_hz": f_lo, "f_max_hz": f_hi, "period_s": 1.0 / spacing, "rms": 1.0}
    clock = max(1, int(math.floor(fs / (3.0 * f[-1]))))
    min_period = 5.0 * fs / f[0]  # lines 0.2 f_1 apart
    bits = min(20, max(5, int(math.ceil(math.log2(min_period / clock + 1)))))
    return {"type": "prbs", "register_bits": bits, "clock_period": clock, "amplitude": 1.0}


def prbs_sequence(bits, clock, amplitude):
    """The simulator's Fibonacci LFSR (its taps table), levels held for `clock` samples."""
    taps = {2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5),
            10: (10, 7), 11: (11, 9), 12: (12, 6, 4, 1), 13: (13, 4, 3, 1), 14: (14, 5, 3, 1), 15: (15, 14),
            16: (16, 15, 13, 4), 17: (17, 14), 18: (18, 11), 19: (19, 6, 2, 1), 20: (20, 17)}[bits]
    mask = (1 << bits) - 1
    reg = mask
    out = np.empty((1 << bits) - 1)
    for k in range(len(out)):
        bit = 0
        for t in taps:
            bit ^= (reg >> (t - 1)) & 1
        reg = ((reg << 1) | bit) & mask
        out[k] = amplitude if bit else -amplitude
    return np.repeat(out, clock)


def lines(sig, fs):
    """(w [rad/sample], complex amplitude c) with x(k) = sum Re(c e^{j w k}) in steady state."""
    if sig["type"] == "sum_of_sines":
        w = np.array(sig["frequencies_rad_s"]) / fs
        return w, np.array(sig["amplitudes"], dtype=complex)
    if sig["type"] == "multisine":
        P = sig["period_s"]
        k = np.arange(max(1, math.ceil(sig["f_min_hz"] * P - 1e-9)), math.floor(sig["f_max_hz"] * P + 1e-9) + 1)
        amp = sig["rms"] * math.sqrt(2.0 / len(k))
        return 2 * math.pi * k / P / fs, np.full(len(k), amp, dtype=complex)
    if sig["type"] == "square":
        P = sig["period_samples"]
        x = np.where((np.arange(P) / P) % 1.0 < 0.5, sig["amplitude"], -sig["amplitude"])
    else:
        x = prbs_sequence(sig["register_bits"], sig["clock_period"], sig["amplitude"])
        P = len(x)
    X = np.fft.rfft(x) / P
    m = np.arange(1, len(X))
    c = 2.0 * X[1:]
    if P % 2 == 0:
        c[-1] = X[-1]  # Nyquist line: not doubled
    keep = np.abs(c) > 1e-12 * np.abs(c).max()
    return 2 * math.pi * m[keep] / P, c[keep]


def input_lines(sig, fs, modes, controller, T):
    """The lines of u in open loop, of u_r = C / (1 + C G) r in closed loop."""
    w, c = lines(sig, fs)
    if controller is None:
        return w, c
    zi = np.exp(-1j * w)
    num, den = controller["numerator"], controller["denominator"]
    C = (num[0] + num[1] * zi) / (den[0] + den[1] * zi)
    return w, c * C / (1.0 + C * plant_response(modes, T, w))


# ---------------------------------------------------------------- Cramer-Rao bound

def information(modes, T, w, c):
    """Per-sample R = mean psi psi^T, psi = d y / d ln(wn, zeta, gain) of every mode; output power."""
    g = []
    for m in modes:
        for q in QUANTITIES:
            h = 1e-6
            up, dn = dict(m), dict(m)
            up[q] *= math.exp(h)
            dn[q] *= math.exp(-h)
            g.append((mode_response(up["wn"], up["zeta"], up["gain"], T, w)
                      - mode_response(dn["wn"], dn["zeta"], dn["gain"], T, w)) / (2 * h) * c)
    g = np.array(g)
    R = 0.5 * np.real(g @ np.conj(g).T)
    y = plant_response(modes, T, w) * c
    return R, 0.5 * float(np.sum(np.abs(y) ** 2))


def cramer_rao(modes, T, w, c, noise_variance, samples):
    R, _ = information(modes, T, w, c)
    F = R * samples / noise_variance
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))
    Fn = F / np.outer(scale, scale)  # unit diagonal: rank and condition free of units
    ev = np.linalg.eigvalsh(Fn)
    cov = np.linalg.pinv(Fn, rcond=1e-10, hermitian=True) / np.outer(scale, scale)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    K = len(modes)
    alone = []
    for i in range(K):
        b = slice(3 * i, 3 * i + 3)
        alone.append(np.sqrt(np.diag(np.linalg.pinv(F[b, b], rcond=1e-10, hermitian=True))))
    small = ev < 1e-10 * ev.max()
    v = np.linalg.eigh(Fn)[1][:, 0]
    names = [f"{m['name']}_{q}" for m in modes for q in QUANTITIES]
    open_dir = {names[j]: round(float(v[j]), 4) for j in np.argsort(-np.abs(v))[:4]}
    return {
        "modes": [{"name": m["name"], "wn_rel_std": float(std[3 * i]), "zeta_rel_std": float(std[3 * i + 1]),
                   "gain_rel_std": float(std[3 * i + 2]), "wn_rel_std_alone": float(alone[i][0]),
                   "zeta_rel_std_alone": float(alone[i][1]), "gain_rel_std_alone": float(alone[i][2])}
                  for i, m in enumerate(modes)],
        "fisher_rank": int(np.sum(~small)), "parameters": 3 * K,
        "fisher_condition": float(ev.max() / max(ev.min(), 1e-300)),
        "weakest_direction": open_dir,
    }


# ---------------------------------------------------------------- faults

def draw_fault(rng, modes, memory_s, scale):
    sc = SCALES[scale]
    i = int(rng.integers(len(modes)))
    u = rng.uniform()
    kind = "stiffness" if u < 0.5 else "damping" if u < 0.75 else "gain"
    m = modes[i]
    if kind == "stiffness":
        size = rng.uniform(0.03, 0.20)
        after = {"wn": m["wn"] * math.sqrt(1.0 - size), "gain": m["gain"] / (1.0 - size)}
    elif kind == "damping":
        size = float(rng.choice([0.5, 2.0]))
        after = {"zeta": m["zeta"] * size}
    else:
        size = float(rng.choice([0.8, 1.2]))
        after = {"gain": m["gain"] * size}
    shape = "step" if rng.uniform() < 0.5 else "ramp"
    start = rng.uniform(*sc["change"]) * memory_s
    ramp = log_uniform(rng, *sc["ramp"]) * memory_s if shape == "ramp" else 0.0
    return {"kind": kind, "mode": m["name"], "mode_index": i, "size": size, "shape": shape,
            "t_start": start, "ramp_s": ramp, "before": {q: m[q] for q in after}, "after": after,
            "relative_change": {q: after[q] / m[q] - 1.0 for q in after}}


# ---------------------------------------------------------------- YAML

def yaml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(yaml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {yaml_value(x)}" for k, x in v.items()) + "}"
    return str(v)


def yaml_block(d, indent=0):
    out = []
    pad = " " * indent
    for k, v in d.items():
        if isinstance(v, dict) and not v.get("_flow"):
            out.append(f"{pad}{k}:")
            out += yaml_block(v, indent + 2)
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            out.append(f"{pad}{k}:")
            for item in v:
                sub = yaml_block(item, indent + 4)
                out.append(f"{pad}  - " + sub[0].lstrip())
                out += sub[1:]
        else:
            if isinstance(v, dict):
                v = {a: b for a, b in v.items() if a != "_flow"}
            out.append(f"{pad}{k}: {yaml_value(v)}")
    return out


# ---------------------------------------------------------------- one scenario

def make_scenario(rng, index, healthy, closed, poor, scale):
    sc = SCALES[scale]
    redraws = {"plant": 0, "excitation": 0, "controller": 0}
    while True:
        fs, modes = draw_plant(rng)
        T = 1.0 / fs
        N = int(round(MEMORY_PERIODS * 2 * math.pi / (modes[0]["wn"] * T)))
        memory_s = N * T
        fault = None if healthy else draw_fault(rng, modes, memory_s, scale)
        controller = None
        if closed:
            plants = [modes]
            if fault:
                faulted = [dict(m) for m in modes]
                faulted[fault["mode_index"]].update(fault["after"])
                plants.append(faulted)
            design = design_controller(plants, T)
            if design is None:
                redraws["controller"] += 1
                continue
            num, den = pi_controller(design["kp"], design["ki"], T)
            controller = {"numerator": num, "denominator": den, **design}
        for _ in range(8):
            sig = draw_excitation(rng, modes, fs, poor)
            snr = rng.uniform(20.0, 60.0)
            w, c = input_lines(sig, fs, modes, controller, T)
            _, power = information(modes, T, w, c)
            noise_variance = power / 10 ** (snr / 10)
            crb = cramer_rao(modes, T, w, c, noise_variance, N)
            if all(m["wn_rel_std"] <= CRB_WN_MAX and m["zeta_rel_std"] <= CRB_ZETA_MAX for m in crb["modes"]):
                return dict(fs=fs, T=T, modes=modes, N=N, memory_s=memory_s, fault=fault, controller=controller,
                            excitation=sig, snr_db=snr, noise_variance=noise_variance, output_power=power,
                            crb=crb, redraws=redraws)
            redraws["excitation"] += 1
        redraws["plant"] += 1


def scenario_files(s, index, seed, scale, loop_name, richness):
    rng = np.random.default_rng([seed, index, 7])
    sc = SCALES[scale]
    M = s["memory_s"]
    fault = s["fault"]
    duration = sc["healthy"] * M if fault is None else \
        fault["t_start"] + fault["ramp_s"] + rng.uniform(*sc["after"]) * M
    lam = 1.0 - 1.0 / s["N"]
    plant_modes = []
    for i, m in enumerate(s["modes"]):
        pm = {"name": m["name"], "kind": "mode", "wn": m["wn"], "zeta": m["zeta"], "gain": m["gain"]}
        if fault and fault["mode_index"] == i:
            t0 = fault["t_start"]
            t1 = t0 + max(fault["ramp_s"], s["T"])  # a step lasts one sample
            pm["trajectory"] = {q: [[t0, m[q]], [t1, v]] for q, v in fault["after"].items()}
        plant_modes.append(pm)
    model = []
    for m in s["modes"]:
        model.append({"name": m["name"], "kind": "mode",
                      "wn": m["wn"] * (1 + rng.uniform(-0.03, 0.03)),
                      "zeta": m["zeta"] * (1 + rng.uniform(-0.2, 0.2)),
                      "gain": m["gain"] * (1 + rng.uniform(-0.1, 0.1)),
                      "forgetting": lam})
    sig = {k: v for k, v in s["excitation"].items() if k != "period_samples"}
    cfg = {"sample_rate_hz": s["fs"],
           "model": {"loop": loop_name, "submodels": model}}
    if s["controller"]:
        cfg["controller"] = {"numerator": s["controller"]["numerator"],
                             "denominator": s["controller"]["denominator"]}
    cfg["plant"] = {"noise_variance": s["noise_variance"], "modes": plant_modes}
    cfg["simulation"] = {"duration": duration, "seed": int(rng.integers(1, 2**31)),
                         ("reference" if s["controller"] else "input"): sig}
    cfg["estimator"] = {"warmup": WARMUP_MEMORIES * M, "fit_on_warmup": True}
    hold = HOLD_MEMORIES * M
    publish = max(1, round(PUBLISH_MEMORIES * s["N"])) * s["T"]
    cfg["daemon"] = {"publish_period": publish}
    cfg["faults"] = {"learn_window": LEARN_MEMORIES * M, "false_alarm_interval": FALSE_ALARM_INTERVAL_H}
    for q, th in THRESHOLDS.items():
        cfg["faults"][q] = {"_flow": True, **th, "hold": hold, "clear_time": hold}
    meta = {
        "index": index, "scale": scale, "healthy": fault is None,
        "class": "healthy" if fault is None else f"{fault['kind']}",
        "loop": loop_name, "excitation_class": richness, "excitation": s["excitation"],
        "sample_rate_hz": s["fs"], "duration_s": duration, "truth": s["modes"],
        "wnT": [m["wn"] * s["T"] for m in s["modes"]],
        "memory_samples": s["N"], "memory_s": M, "lambda": lam,
        "warmup_s": WARMUP_MEMORIES * M, "learn_window_s": LEARN_MEMORIES * M, "hold_s": hold,
        "publish_period_s": publish, "false_alarm_interval_h": FALSE_ALARM_INTERVAL_H,
        "thresholds": THRESHOLDS, "snr_db": s["snr_db"], "noise_variance": s["noise_variance"],
        "output_power": s["output_power"], "controller": s["controller"], "fault": fault,
        "nominal_model": [{k: v for k, v in m.items() if k in ("name", "wn", "zeta", "gain")} for m in model],
        "cramer_rao_one_memory": s["crb"], "redraws": s["redraws"],
    }
    header = (f"# Scenario {index} of a randomised bank (scripts/study/scenario_bank.py, seed {seed}, "
              f"scale {scale}): {meta['class']}, {loop_name} loop, {richness} excitation.\n"
              f"# Memory {s['N']} samples = {M:.6g} s (50 periods of the slowest mode); "
              f"durations in the estimator and faults sections are multiples of it.\n")
    return header + "\n".join(yaml_block(cfg)) + "\n", meta


def default_binary():
    here = os.path.dirname(os.path.abspath(__file__))
    local = os.path.join(here, "..", "..", "build", "modalwatch")
    return local if os.path.exists(local) else (shutil.which("modalwatch") or local)


def binary_path(name):
    """A path given with a folder is made absolute (the scenarios run in their own folders)."""
    return os.path.abspath(name) if os.sep in name else name


def generate(args):
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    n = args.count
    healthy = np.zeros(n, bool) if args.faults_only else np.ones(n, bool) if args.healthy_only else \
        rng.permutation(np.arange(n) % 2 == 0)
    closed = rng.permutation(np.arange(n) % 2 == 1)
    poor = rng.permutation(np.arange(n) % 3 == 2)
    for i in range(n):
        if (args.skip_healthy and healthy[i]) or (args.skip_faults and not healthy[i]):
            continue
        t0 = time.time()
        s = make_scenario(np.random.default_rng([args.seed, i]), i, healthy[i], closed[i], poor[i], args.scale)
        loop_name = "closed" if closed[i] else "open"
        richness = "poor" if poor[i] else "rich"
        cfg, meta = scenario_files(s, i, args.seed, args.scale, loop_name, richness)
        sid = f"{i:04d}-{meta['class']}-{loop_name}-{richness}"
        d = os.path.join(args.out, sid)
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, "config.yaml"), "w") as f:
            f.write(cfg)
        t1 = time.time()
        if not args.no_simulate:
            subprocess.run([args.modalwatch, "simulate", "--config", "config.yaml", "--out", "record.csv",
                            "--truth", "truth.csv"], cwd=d, check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE)
        meta["id"] = sid
        meta["seconds"] = {"design": t1 - t0, "simulate": time.time() - t1}
        with open(os.path.join(d, "meta.json"), "w") as f:
            json.dump(meta, f, indent=1)
        worst = max(m["wn_rel_std"] for m in s["crb"]["modes"])
        print(f"{sid}: K={len(s['modes'])} fs={s['fs']:.0f} Hz N={s['N']} duration={meta['duration_s']:.4g} s "
              f"({meta['duration_s'] / s['memory_s']:.1f} M) snr={s['snr_db']:.0f} dB "
              f"crb wn<={100 * worst:.3f} % redraws={s['redraws']} "
              f"[{t1 - t0:.1f} s design, {time.time() - t1:.1f} s simulate]", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="draw scenarios, write their configs and simulate them")
    g.add_argument("--out", required=True)
    g.add_argument("--count", type=int, required=True)
    g.add_argument("--seed", type=int, default=1)
    g.add_argument("--scale", choices=sorted(SCALES), default="full")
    only = g.add_mutually_exclusive_group()
    only.add_argument("--healthy-only", action="store_true")
    only.add_argument("--faults-only", action="store_true")
    only.add_argument("--skip-healthy", action="store_true", help="the same bank's fault records only")
    only.add_argument("--skip-faults", action="store_true", help="the same bank's healthy records only")
    g.add_argument("--modalwatch", default=default_binary(), type=binary_path)
    g.add_argument("--no-simulate", action="store_true", help="write config.yaml and meta.json only")
    args = p.parse_args()
    generate(args)


if __name__ == "__main__":
    sys.exit(main())
