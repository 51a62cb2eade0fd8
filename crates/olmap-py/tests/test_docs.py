"""help() documents every argument with units and defaults; the stubs match the module."""

import inspect
import re
import pathlib

import olmap

PUBLIC_FUNCTIONS = [
    olmap.read_cloud, olmap.write_cloud, olmap.read_poses, olmap.align, olmap.localize,
    olmap.build_map, olmap.simulate, olmap.map_team, olmap.detect_beacons,
    olmap.mutual_localisation,
]
CLASSES = [
    olmap.PointCloud, olmap.Alignment, olmap.OccupancyMap, olmap.FreeSpaceMap, olmap.MapBuild, olmap.SimDataset,
    olmap.TeamResult, olmap.Localizer,
]


def args_entries(doc):
    """The entries of a docstring's Args section: name -> its text."""
    section = doc.split("Args:", 1)[1].split("\n\n", 1)[0]
    entries, current = {}, None
    for line in section.splitlines():
        m = re.match(r"^ {4}(\w+(?:, \w+)*): ?(.*)", line)
        if m:
            current = m.group(1)
            entries[current] = m.group(2)
        elif current:
            entries[current] += " " + line.strip()
    return {n.strip(): text for names, text in entries.items() for n in names.split(",")}


def test_align_documents_every_argument_with_units_and_defaults():
    doc = olmap.align.__doc__
    entries = args_entries(doc)
    sig = inspect.signature(olmap.align)
    for name, p in sig.parameters.items():
        assert name in entries, name
        if p.default is not inspect.Parameter.empty:
            assert "default" in entries[name].lower(), (name, entries[name])
    for name in ("resolution", "max_range"):
        assert "metres" in entries[name]
    assert "degrees" in entries["max_tilt"] and "degrees" in entries["window"]
    assert str(sig).startswith("(source, target, resolution=0.1, dof='xyz-yaw', max_tilt=15.0")


def test_every_function_and_class_has_a_docstring_and_a_signature():
    for f in PUBLIC_FUNCTIONS:
        assert f.__doc__ and len(f.__doc__) > 100, f.__name__
        inspect.signature(f)  # a text signature is attached
        entries = args_entries(f.__doc__)
        for name in inspect.signature(f).parameters:
            assert name in entries, f"{f.__name__}: {name} has no Args entry"
    for c in CLASSES:
        assert c.__doc__ and len(c.__doc__) > 40, c.__name__
    assert olmap.__doc__ and "metres" in olmap.__doc__


def test_the_stubs_name_every_public_item():
    stub = (pathlib.Path(olmap.__file__).parent / "__init__.pyi").read_text()
    assert (pathlib.Path(olmap.__file__).parent / "py.typed").is_file()
    for name in olmap.__all__:
        if name == "__version__":
            continue
        assert f"def {name}(" in stub or f"class {name}" in stub, name
    for f in PUBLIC_FUNCTIONS:
        for name in inspect.signature(f).parameters:
            assert f"{name}:" in stub.split(f"def {f.__name__}(", 1)[1].split("...", 1)[0], (
                f.__name__,
                name,
            )
