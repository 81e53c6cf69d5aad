"""Fuzz: mutated robot YAML files and random URDF graphs (loops, cycles, several trees,
odd axes and limits) through fk, import-urdf and calibrate (issue 21)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from tests.cli_contract import check_contract, leftovers, run_kinecal
from tests.fuzz.strategies import FUZZ, mutated_doc, mutated_text

ZEROS = ["0"] * 6


def _robot_doc():
    from kinecal.robot import dump_robot, load_robot

    return dump_robot(load_robot("fanuc-lrmate200id"))


def test_issue_21_fuzz_robot_yaml(point_data, capsys, tmp_path):
    from kinecal import _yaml as yaml

    doc = _robot_doc()
    text = yaml.dump(doc, sort_keys=False)

    @FUZZ
    @given(
        robot=st.one_of(
            mutated_doc(doc).map(lambda d: yaml.dump(d, sort_keys=False)),
            mutated_text(text),
        )
    )
    def check(robot: str) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / "robot.yaml"
        f.write_text(robot)
        check_contract(run_kinecal(capsys, "fk", "--robot", f, "--json", "--", *ZEROS))
        res = run_kinecal(
            capsys,
            "calibrate",
            point_data["train"],
            "--robot",
            f,
            "--model",
            "kinematic",
            "--out",
            d / "cal",
            "--no-report",
            "-q",
        )
        check_contract(res)
        assert (d / "cal").exists() == (res.code in (0, 3)), str(res)
        assert not leftovers(d)

    check()


_TYPES = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "hinge"]
_VEC = st.one_of(
    st.sampled_from(["0 0 1", "0 1 0", "1 0 0", "0 0 -1", "0 0 0", "1 1", "a b c"]),
    st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).map(
        lambda v: " ".join(f"{x:.3f}" for x in v)
    ),
    st.just("nan 0 1"),
)
_XYZ = st.one_of(
    st.tuples(*[st.floats(-0.5, 0.5, allow_nan=False)] * 3).map(
        lambda v: " ".join(f"{x:.4f}" for x in v)
    ),
    st.sampled_from(["0 0 0", "0 0 0.3", "inf 0 0", "x", ""]),
)


@st.composite
def urdf_graph(draw: st.DrawFn) -> str:
    """A URDF of random links and joints. Half are clean serial chains (which import);
    the rest trees, forests, loops, cycles, joints to undefined links, odd joint types,
    axes, origins and limits."""
    clean = draw(st.booleans())
    n_links = draw(st.integers(3 if clean else 1, 8))
    links = [f"l{i}" for i in range(n_links)]
    shape = (
        "chain"
        if clean
        else draw(st.sampled_from(["chain", "random", "loop", "cycle", "split"]))
    )
    edges = []
    if shape in ("chain", "loop", "cycle", "split"):
        edges = [(f"l{i}", f"l{i + 1}") for i in range(n_links - 1)]
        if shape == "loop" and n_links > 2:
            edges.append(("l0", f"l{n_links - 1}"))  # a link below two joints
        if shape == "cycle" and n_links > 2:
            edges[0] = (f"l{n_links - 1}", "l1")  # l1 .. l(n-1) -> l1
        if shape == "split" and n_links > 3:
            del edges[n_links // 2]  # two trees
    else:
        for _ in range(draw(st.integers(0, 10))):
            a = draw(st.sampled_from([*links, "ghost"]))
            b = draw(st.sampled_from([*links, "ghost"]))
            edges.append((a, b))
    parts = [f'<robot name="{draw(st.sampled_from(["r", "", "x y"]))}">']
    parts += [f'<link name="{lk}"/>' for lk in links]
    good_axes = st.sampled_from(["0 0 1", "0 1 0", "1 0 0", "0 0 -1", "0.6 0 0.8"])
    good_xyz = st.tuples(*[st.floats(-0.5, 0.5, allow_nan=False)] * 3).map(
        lambda v: " ".join(f"{x:.4f}" for x in v)
    )
    for k, (a, b) in enumerate(edges):
        if clean:
            kind = "revolute" if k == 0 else draw(st.sampled_from(_TYPES[:4]))
            lo, hi = ("-3.1", "3.1")
            axis = "0 0 1" if k == 0 else draw(good_axes)
            xyz = "0 0 0" if k == 0 else draw(good_xyz)
        else:
            kind = draw(st.sampled_from(_TYPES[:4]) if k else st.sampled_from(_TYPES))
            lo, hi = draw(
                st.sampled_from([("-2", "2"), ("2", "-2"), ("a", "1"), ("-1", "nan")])
                | st.just(("-3.1", "3.1"))
            )
            axis = draw(_VEC) if k else draw(st.sampled_from(["0 0 1", "0 0 0"]))
            xyz = draw(_XYZ) if k else "0 0 0"
        parts.append(
            f'<joint name="j{k}" type="{kind}"><parent link="{a}"/><child link="{b}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>'
        )
    parts.append("</robot>")
    text = "".join(parts)
    if not clean and draw(st.integers(0, 9)) == 0:
        text = text[: draw(st.integers(0, len(text)))]  # cut short
    return text


def test_issue_21_fuzz_urdf(capsys, tmp_path):
    @FUZZ
    @given(urdf=urdf_graph())
    def check(urdf: str) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / "robot.urdf"
        f.write_text(urdf)
        res = run_kinecal(capsys, "import-urdf", f, "--out", d / "robot.yaml")
        check_contract(res)
        assert (d / "robot.yaml").exists() == (res.code == 0), str(res)
        n_movable = urdf.count('type="revolute"') + urdf.count('type="prismatic"')
        n_movable += urdf.count('type="continuous"')
        for n in {2, 6, n_movable}:
            check_contract(
                run_kinecal(
                    capsys,
                    "fk",
                    "--robot",
                    f,
                    "--json",
                    "--ignore-limits",
                    "--",
                    *["0.1"] * n,
                )
            )
        assert not leftovers(d)

    check()
