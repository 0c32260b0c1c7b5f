import subprocess
import sys

import pytest

import torchcbl


def test_unknown_attribute_is_a_clear_error():
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        torchcbl.Nope  # noqa: B018


def test_core_never_imports_a_simulator_or_a_domain():
    code = (
        "import sys, torchcbl\n"
        "for name in list(torchcbl._EXPORTS):\n"
        "    try:\n"
        "        getattr(torchcbl, name)\n"
        "    except (ImportError, AttributeError):\n"
        "        pass\n"
        "bad = [m for m in ('pymunk', 'libsumo', 'traci', 'corridor', 'sumo_scenarios')\n"
        "       if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_mean_sd_by_hand():
    from torchcbl.evaluation import mean_sd, run_versions

    assert mean_sd([1.0, 2.0, 3.0, None]) == {"mean": 2.0, "sd": 1.0, "n": 3}
    assert mean_sd([5]) == {"mean": 5.0, "sd": 0.0, "n": 1}
    assert mean_sd([None]) == {"mean": None, "sd": None, "n": 0}
    v = run_versions(sim="1.2")
    assert v["sim"] == "1.2" and v["torchcbl"] == torchcbl.__version__
