"""The compiled kernel and the same code interpreted (TUAV_NO_JIT=1) are one model."""


import numpy as np
from jit_util import run_script

SCRIPT = """
import json
import numpy as np
from sitl import _jit
from sitl.plant import Plant
from sitl.trim import hover_trim
from tuavdefs.params import SystemParams, WindParams
params = SystemParams().replace(wind=WindParams(steady_m_s=(2.0, 1.0, 0.0),
                                                turbulence="moderate", seed=3))
x, u = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
u = u._replace(rotor_commands=(0.64, 0.62, 0.63, 0.65), winder_enabled=True,
               winder_torque_n_m=-0.2)
plant = Plant(params, state=x)
for _ in range(400):
    plant.step(u)
print(json.dumps({"jit": _jit.JIT, "x": plant.x.tolist()}))
"""


def _run(no_jit: bool) -> dict:
    return run_script(SCRIPT, no_jit, 300)


def test_compiled_and_interpreted_kernels_agree():
    compiled, interpreted = _run(False), _run(True)
    assert compiled["jit"] is True and interpreted["jit"] is False
    a, b = np.array(compiled["x"]), np.array(interpreted["x"])
    assert np.allclose(a, b, rtol=1e-9, atol=1e-12)
    assert not np.allclose(a[:3], (12.0, 5.0, 20.0), atol=1e-3)   # it really moved
