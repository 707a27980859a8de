"""Shared fixtures: a seeded test volume, a bent lattice, and the CLI binary."""

import os
import pathlib
import shutil

import numpy as np
import pytest

import volmorph as vm

ROOT = pathlib.Path(__file__).resolve().parents[2]

# A proper rotation (30° about z, then 20° about x): a non-identity direction matrix.
_c, _s = np.cos(np.radians(30)), np.sin(np.radians(30))
_C, _S = np.cos(np.radians(20)), np.sin(np.radians(20))
ROTATION = np.array([[1, 0, 0], [0, _C, -_S], [0, _S, _C]]) @ np.array(
    [[_c, -_s, 0], [_s, _c, 0], [0, 0, 1]]
)


def blob(shape=(13, 11, 9), dtype=np.float32, direction=None):
    """A smooth blob with noise on an anisotropic, offset (optionally rotated) grid."""
    rng = np.random.default_rng(7)
    z, y, x = np.meshgrid(*[np.linspace(-1, 1, n) for n in shape], indexing="ij")
    a = 100 * np.exp(-3 * (x**2 + 1.5 * y**2 + 2 * z**2)) + rng.normal(0, 2, shape)
    if np.issubdtype(dtype, np.integer):
        a = np.clip(a, 0, None)
    return vm.Volume(
        np.ascontiguousarray(a.astype(dtype)),
        spacing=(0.9, 1.1, 1.7),
        origin=(-4.0, -5.5, -10.0),
        direction=(ROTATION if direction is None else direction).tolist(),
    )


def bent_lattice(volume, counts=(5, 5, 5), amount=2.0, seed=3):
    """The identity lattice over `volume` with its interior control points moved at random."""
    m = vm.Map.lattice(volume.geometry, counts)
    cp = m.control_points.copy()
    rng = np.random.default_rng(seed)
    cp[1:-1, 1:-1, 1:-1] += rng.uniform(-amount, amount, cp[1:-1, 1:-1, 1:-1].shape)
    return m.with_control_points(cp)


@pytest.fixture
def volume():
    return blob()


@pytest.fixture
def lattice(volume):
    return bent_lattice(volume)


@pytest.fixture(scope="session")
def cli():
    """The `volmorph` binary: $VOLMORPH, else target/debug or target/release; skip if none."""
    for c in [
        os.environ.get("VOLMORPH"),
        ROOT / "target" / "debug" / "volmorph",
        ROOT / "target" / "release" / "volmorph",
        shutil.which("volmorph"),
    ]:
        if c and pathlib.Path(c).is_file():
            return str(c)
    pytest.skip("the volmorph binary is not built (cargo build -p volmorph-cli)")
