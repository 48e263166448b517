from dataclasses import dataclass, field
from enum import Enum

import pytest

from holoslam.config import from_mapping, load_yaml_config, to_mapping
from holoslam.errors import ConfigError


class Kernel(Enum):
    HUBER = "huber"
    CAUCHY = "cauchy"


@dataclass(frozen=True)
class Inner:
    sigma: float = 0.1
    kernel: Kernel = Kernel.HUBER


@dataclass(frozen=True)
class Outer:
    name: str = "x"
    steps: int = 3
    inner: Inner = field(default_factory=Inner)
    scales: tuple[float, ...] = (1.0,)


def test_round_trip_through_mapping():
    cfg = from_mapping(Outer, {"steps": 5, "inner": {"kernel": "cauchy", "sigma": 2}, "scales": [1, 2.5]})
    assert cfg == Outer(steps=5, inner=Inner(sigma=2.0, kernel=Kernel.CAUCHY), scales=(1.0, 2.5))
    assert from_mapping(Outer, to_mapping(cfg)) == cfg


@pytest.mark.parametrize(
    "data, needle",
    [
        ({"stepz": 1}, "did you mean 'steps'"),
        ({"steps": "three"}, "config.steps: expected an integer"),
        ({"steps": True}, "expected an integer"),
        ({"inner": {"kernel": "l2"}}, "config.inner.kernel: 'l2' is not one of"),
        ({"inner": {"sigma": float("nan")}}, "finite"),
        ({"inner": 3}, "expected a mapping"),
    ],
)
def test_nonsense_is_named(data, needle):
    with pytest.raises(ConfigError, match=needle):
        from_mapping(Outer, data)


def test_yaml_file_errors(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("steps: [1, 2\n")
    with pytest.raises(ConfigError, match=r"not valid YAML at line"):
        load_yaml_config(Outer, p)
    p.write_text("- a\n- b\n")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        load_yaml_config(Outer, p)
    p.write_text("!!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(ConfigError):
        load_yaml_config(Outer, p)
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_yaml_config(Outer, tmp_path / "missing.yaml")
    p.write_text("steps: 7\n")
    assert load_yaml_config(Outer, p).steps == 7


def test_solver_method_is_the_solver_enum_and_lm_reads_as_batch():
    from holoslam.choices import Method
    from holoslam.config import RunConfig, from_mapping

    assert RunConfig().solver.method is Method.BATCH
    assert from_mapping(RunConfig, {"solver": {"method": "lm"}}).solver.method is Method.BATCH
    assert from_mapping(RunConfig, {"solver": {"method": "ISAM2"}}).solver.method is Method.ISAM2
    with pytest.raises(ConfigError, match=r"config.solver.method: 'gauss' is not one of \['batch', 'isam2'\]"):
        from_mapping(RunConfig, {"solver": {"method": "gauss"}})
