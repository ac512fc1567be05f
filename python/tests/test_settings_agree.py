"""The reconstruction settings agree across the front ends: the Python keywords (the
library's ``settings::SETTINGS``), the CLI's flags, the stubs and the README table name
the same settings, with the same defaults and units; and each setting changed from its
default gives the same mesh through the CLI and through Python.

A new setting fails here until it is a flag, a keyword, a stub entry and a README row,
and until ``CHANGED`` holds a value for it."""

import ast
import re
import subprocess

import numpy as np
import pytest

import meniscus
from conftest import ROOT, cli_command, run_cli

PARTICLES = ROOT / "datasets" / "analytic" / "droplets.xyz"
R = 0.025

# For every setting, a value other than its default: as the CLI's flag takes it, and as
# the Python keyword takes it ("TMP" stands for a temporary directory).
CHANGED = {
    "influence_radius": ("3.5", 3.5),
    "cell_size": ("1.25", 1.25),
    "t_low": ("0.5", 0.5),
    "t_high": ("3", 3.0),
    "particle_coverage": ("0.8", 0.8),
    "iso_offset": ("0.05", 0.05),
    "kernel": ("isotropic", "isotropic"),
    "kernel_radius": ("3", 3.0),
    "max_stretch": ("1.5", 1.5),
    "min_neighbours": ("6", 6),
    "centre_smoothing": ("0.2", 0.2),
    "isolated_spheres": ("1", 1),
    "decimate": ("0.5", 0.5),
    "decimate_error": ("0.2", 0.2),
    "smooth": ("1", 1),
    "smooth_method": ("laplacian", "laplacian"),
    "smooth_max_inward": ("0.3", 0.3),
    "smooth_feature_angle": ("9", 9.0),
    "subdivide": ("0", 0),
    "keep_inside": ("0.5", 0.5),
    "normal_smoothing": ("2", 2),
    "tile_size": ("8", 8),
    "memory_budget": ("1GiB", "1GiB"),
    "temp_dir": ("TMP", "TMP"),
}
# Settings that take effect only beside another one: that one, as flag and keyword.
BESIDE = {"smooth_feature_angle": ("smooth_method", "laplacian")}

# Keywords without a flag: the CLI defers subdivision by itself for a .mseq output.
PYTHON_ONLY = {"defer_subdivision"}
MULTIPLES_OF_R = "multiples of r"


def python_settings():
    """The reconstruction keywords, in order, as Python lists them when refusing one."""
    with pytest.raises(TypeError) as refused:
        meniscus.reconstruct(np.zeros((2, 3), np.float32), R, no_such_setting=1)
    return str(refused.value).split("the reconstruction options are ")[1].split(", ")


def cli_flags():
    """`meniscus reconstruct --help`: each long flag's help text, on one line."""
    help_text = subprocess.run(
        cli_command("reconstruct", "--help"), cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    flags = {}
    for block in re.split(r"\n(?=\s{2,6}(?:-\w, )?--)", help_text):
        found = re.match(r"\s*(?:-\w, )?--([\w-]+)", block)
        if found:
            flags[found.group(1)] = " ".join(block.split())
    return flags


def cli_default(help_text):
    found = re.search(r"\[default: ([^\];]+)", help_text)
    return found.group(1) if found else None


def stub_settings():
    """The stubs' ReconstructOptions: name -> docstring, in order."""
    tree = ast.parse((ROOT / "python" / "meniscus.pyi").read_text())
    options = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "ReconstructOptions")
    docs, last = {}, None
    for node in options.body:
        if isinstance(node, ast.AnnAssign):
            last = node.target.id
            docs[last] = ""
        elif isinstance(node, ast.Expr) and last is not None:
            docs[last] = " ".join(node.value.value.split())
    return docs


def stub_default(doc):
    found = re.search(r'\bDefault (?:``")?([\w.]*\w)', doc)
    return found.group(1) if found else None


def readme_rows():
    """The README's option rows: flag -> (unit, default) of the row naming it."""
    rows = {}
    for line in (ROOT / "README.md").read_text().splitlines():
        # Cells split at the pipes that are not escaped (`--decimate F\|adaptive\|off`).
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]] if line.startswith("| `") else []
        if len(cells) >= 4:
            for flag in re.findall(r"--([\w-]+)", cells[0]):
                rows.setdefault(flag, (cells[1], cells[2]))
    return rows


def test_the_front_ends_name_the_same_settings():
    names = python_settings()
    assert list(stub_settings()) == names, "the stubs' ReconstructOptions"
    reconstruct_doc = ast.get_docstring(
        next(n for n in ast.parse((ROOT / "python" / "meniscus.pyi").read_text()).body
             if isinstance(n, ast.FunctionDef) and n.name == "reconstruct"))
    listed = reconstruct_doc.split("**options: the reconstruction settings (``ReconstructOptions``):")[1]
    assert re.findall(r"\w+", listed.split("\n\n")[0]) == names, "reconstruct's **options list"
    flags, readme = cli_flags(), readme_rows()
    for name in names:
        if name in PYTHON_ONLY:
            continue
        flag = name.replace("_", "-")
        assert flag in flags, f"--{flag}"
        assert flag in readme, f"README row of --{flag}"
    assert set(CHANGED) == set(names) - PYTHON_ONLY, "CHANGED holds a value for every setting"


def test_defaults_and_units_agree():
    flags, stubs, readme = cli_flags(), stub_settings(), readme_rows()
    for name in set(stubs) - PYTHON_ONLY:
        flag = name.replace("_", "-")
        default = cli_default(flags[flag])
        # Python's None is the CLI's `off`.
        stub = {"None": "off"}.get(stub_default(stubs[name]), stub_default(stubs[name]))
        assert stub == default, f"{name}: the stub's default, --{flag}'s {default}"
        unit, readme_default = readme[flag]
        if default is not None:
            assert re.search(rf"(^|[ ,]){re.escape(default)}($|[;, ])", readme_default), (
                f"README's default of --{flag} ({readme_default!r}) is not {default}"
            )
        in_r = MULTIPLES_OF_R in flags[flag]
        assert (MULTIPLES_OF_R in stubs[name]) == in_r, f"{name}: the stub's unit"
        assert (unit == MULTIPLES_OF_R) == in_r, f"--{flag}: the README's unit {unit!r}"


def python_value(name, text):
    """The CLI's text `text` of setting `name` as the Python keyword takes it."""
    if text == "off":
        return None
    kind = type(CHANGED[name][1])
    return kind(float(text)) if kind is int else kind(text)


def test_python_defaults_are_the_clis():
    # Each setting given its CLI default explicitly leaves the mesh as without it.
    points = np.fromfile(PARTICLES, dtype="<f4").reshape(-1, 3)
    plain = meniscus.reconstruct(points, R)
    flags = cli_flags()
    for name in CHANGED:
        default = cli_default(flags[name.replace("_", "-")])
        if default is None:
            continue
        mesh = meniscus.reconstruct(points, R, **{name: python_value(name, default)})
        assert np.array_equal(mesh.vertices, plain.vertices), name
        assert np.array_equal(mesh.triangles, plain.triangles), name


@pytest.mark.parametrize("name", sorted(CHANGED))
def test_a_changed_setting_means_the_same_in_both(name, tmp_path):
    cli_text, value = CHANGED[name]
    if value == "TMP":
        cli_text = value = str(tmp_path)
    else:
        assert cli_text != cli_default(cli_flags()[name.replace("_", "-")]), "a changed value"
    flag = "--" + name.replace("_", "-")
    beside = dict([BESIDE[name]]) if name in BESIDE else {}
    beside_flags = [a for k, v in beside.items() for a in ("--" + k.replace("_", "-"), v)]
    run_cli("reconstruct", PARTICLES, "-r", R, flag, cli_text, *beside_flags, "-o", tmp_path / "cli.ply", "--quiet")
    meniscus.reconstruct_file(str(PARTICLES), str(tmp_path / "py.ply"), R, **{name: value}, **beside)
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()
