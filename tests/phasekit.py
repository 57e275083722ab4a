"""Running kernels/phase.h on the device for a model Phase: the medium record, its lobes and tables
as volcl packs them, and the test kernels of tests/kernels/sampling_tests.cl."""
from dataclasses import dataclass

import numpy as np

from conftest import run_kernel
from volcl import layout
from volcl.phase import PhasePacker
from volcl.scene.model import Phase

f32, u32 = np.float32, np.uint32


def phase_buffers(phase: Phase):
    """(medium record, lobes, tables) for a homogeneous medium with this phase function."""
    m = np.zeros(1, layout.MEDIUM)
    m["sigma_t"], m["albedo"] = 1.0, 1.0
    m["sigma_t_grid"] = m["albedo_grid"] = -1
    packer = PhasePacker()
    m["phase"], m["g"], m["phase_lobe"], m["phase_lobe_count"] = packer.add(phase)
    lobes, tables = packer.arrays()
    return m, lobes, tables


@dataclass
class Samples:
    d: np.ndarray           # sampled directions (n, 3), float32
    pdf: np.ndarray         # the pdf phase_sample returned
    weight: np.ndarray      # value / pdf phase_sample returned
    value: np.ndarray       # phase_eval_pdf's value of the sampled direction
    eval_pdf: np.ndarray    # phase_eval_pdf's pdf of the sampled direction


def sample(cl_env, prog, phase: Phase, d_in, seed=31, n=1_000_000) -> Samples:
    bufs = phase_buffers(phase)
    d, pdf, value, eval_pdf, weight = run_kernel(
        cl_env, prog, "phase_sample_dirs", n, [(f32, (3,)), (f32, ()), (f32, ()), (f32, ()), (f32, ())],
        u32(seed), inputs=[*bufs, np.asarray(d_in, np.float32)])
    return Samples(d, pdf, weight, value, eval_pdf)


def evaluate(cl_env, prog, phase: Phase, d_in, d_out):
    """(value, pdf) from d_in towards each of d_out (k, 3), on the device."""
    d_out = np.ascontiguousarray(np.asarray(d_out, np.float32).reshape(-1, 3))
    return run_kernel(cl_env, prog, "phase_eval_dirs", len(d_out), [(f32, ()), (f32, ())],
                      inputs=[*phase_buffers(phase), np.asarray(d_in, np.float32), d_out])


def eval_cos(cl_env, prog, phase: Phase, cos_theta):
    c = np.ascontiguousarray(np.asarray(cos_theta, np.float32).ravel())
    (v,) = run_kernel(cl_env, prog, "phase_eval_cos", c.size, [(f32, ())], inputs=[*phase_buffers(phase), c])
    return v.reshape(np.shape(cos_theta))
