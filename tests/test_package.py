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
