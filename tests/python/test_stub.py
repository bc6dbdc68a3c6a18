"""The shipped stub duplex/__init__.pyi imports, and names every public function, class, method and
parameter of the module as the module has them (names, order, which have defaults, and the
defaults themselves where both sides show them)."""
import ast
import importlib.machinery
import importlib.util
import inspect
import pathlib

import pytest

import duplex

STUB_PATH = pathlib.Path(duplex.__file__).with_name("__init__.pyi")
CLASSES = ("Scene", "RaycastingScene", "Array")


@pytest.fixture(scope="module")
def stub():
    assert STUB_PATH.exists(), f"{STUB_PATH} is not shipped beside the package"
    assert STUB_PATH.with_name("py.typed").exists(), "py.typed (PEP 561) is missing beside the stub"
    loader = importlib.machinery.SourceFileLoader("duplex_stub", str(STUB_PATH))
    spec = importlib.util.spec_from_loader("duplex_stub", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)  # the stub is valid Python whose names resolve
    return module


def split_top_level(text):
    parts, depth, cur = [], 0, ""
    for ch in text:
        if ch in "[(":
            depth += 1
        elif ch in "])":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append(cur.strip())
            cur = ""
        else:
            cur += ch
    if cur.strip():
        parts.append(cur.strip())
    return parts


def literal(text):
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return inspect.Parameter.empty  # not comparable (an object's repr)


def runtime_signatures(obj, name):
    """[(parameter name, has default, default)] per overload of a pybind11 or Python callable."""
    if isinstance(obj, property):
        return None
    try:
        sig = inspect.signature(obj)
        return [[(p.name, p.default is not inspect.Parameter.empty, p.default)
                 for p in sig.parameters.values() if p.name not in ("self", "cls")
                 and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]]
    except (ValueError, TypeError):
        pass
    out = []
    for line in (obj.__doc__ or "").splitlines():
        line = line.strip()
        if line[:3].rstrip(". ").isdigit():
            line = line.split(". ", 1)[1]
        if not line.startswith(name + "(") or ") ->" not in line:
            continue
        inner = line[len(name) + 1:line.rindex(") ->")]
        params = []
        for p in split_top_level(inner):
            head, _, default = p.partition("=")
            pname = head.split(":")[0].strip()
            if pname in ("self", "cls"):
                continue
            params.append((pname, bool(_), literal(default.strip()) if _ else inspect.Parameter.empty))
        out.append(params)
    assert out, f"no signature found for {name}"
    return out


def stub_signatures(tree, cls, name):
    """[(parameter name, has default, default)] per definition (overload) of `name` in the stub."""
    body = tree.body
    if cls:
        body = next(n for n in body if isinstance(n, ast.ClassDef) and n.name == cls).body
    out = []
    for node in body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            args = node.args.posonlyargs + node.args.args
            defaults = [None] * (len(args) - len(node.args.defaults)) + node.args.defaults
            params = [(a.arg, d is not None, literal(ast.unparse(d)) if d is not None else inspect.Parameter.empty)
                      for a, d in zip(args, defaults)]
            params += [(a.arg, d is not None, literal(ast.unparse(d)) if d is not None else inspect.Parameter.empty)
                       for a, d in zip(node.args.kwonlyargs, node.args.kw_defaults)]
            out.append([p for p in params if p[0] not in ("self", "cls")])
    return out


def stub_members(tree, cls):
    body = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls).body
    names = {n.name for n in body if isinstance(n, ast.FunctionDef)}
    names |= {n.target.id for n in body if isinstance(n, ast.AnnAssign)}
    return {n for n in names if not n.startswith("_")}


@pytest.fixture(scope="module")
def tree():
    return ast.parse(STUB_PATH.read_text())


def same(runtime, stubbed):
    """Equal names and default presence; equal defaults where both are literals."""
    if len(runtime) != len(stubbed):
        return False
    for (rn, rh, rd), (sn, sh, sd) in zip(runtime, stubbed):
        if rn != sn or rh != sh:
            return False
        if rd is not inspect.Parameter.empty and sd is not Ellipsis and rd != sd:
            return False
    return True


def public(cls):
    return {n for n in dir(cls) if not n.startswith("_")} - set(dir(object))


def test_stub_names_the_module_s_public_names(stub, tree):
    annotated = {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    for name in duplex.__all__:
        assert hasattr(stub, name) or name in annotated, f"duplex.{name} is missing from {STUB_PATH.name}"


@pytest.mark.parametrize("cls", CLASSES)
def test_stub_classes_have_the_runtime_members(tree, cls):
    runtime = getattr(duplex, cls)
    stubbed = stub_members(tree, cls)
    missing = public(runtime) - stubbed
    extra = {n for n in stubbed - public(runtime) if not hasattr(runtime, n)}
    if cls == "Array":  # an ndarray: only the methods duplex adds
        missing = {n for n in missing if n in vars(runtime)}
    if cls == "RaycastingScene":
        extra.discard("scene")  # an instance attribute
    assert not missing and not extra, f"{cls}: missing from the stub {sorted(missing)}, only in the stub {sorted(extra)}"


@pytest.mark.parametrize("cls", CLASSES)
def test_stub_methods_have_the_runtime_parameters(tree, cls):
    runtime = getattr(duplex, cls)
    names = sorted(public(runtime) & stub_members(tree, cls))
    if cls != "Array":
        names.append("__init__")
    else:
        names = [n for n in names if n in vars(runtime)]
    checked = 0
    for name in names:
        r = inspect.getattr_static(runtime, name)
        if isinstance(r, property) or not callable(getattr(runtime, name)) or isinstance(getattr(runtime, name), int):
            continue
        ss = stub_signatures(tree, cls, name)
        if name in ("create_rays_pinhole", "add_triangles"):
            # Open3D's two forms: one Python function that dispatches on its arguments.
            assert len(ss) == 2, f"{cls}.{name}: the stub should show both forms"
            continue
        rs = runtime_signatures(getattr(runtime, name), name)
        assert len(rs) == len(ss) and all(any(same(r, s) for s in ss) for r in rs), \
            f"{cls}.{name}: runtime {rs} != stub {ss}"
        checked += 1
    assert checked >= (25 if cls == "Scene" else 3)


def test_stub_functions_have_the_runtime_parameters(tree):
    for name in ("set_max_memory", "max_memory", "primary_rays", "random_rays", "run_sensors", "run_lighting"):
        rs = runtime_signatures(getattr(duplex, name), name)
        ss = stub_signatures(tree, None, name)
        assert len(rs) == len(ss) and all(any(same(r, s) for s in ss) for r in rs), f"{name}: runtime {rs} != stub {ss}"


def test_help_shows_array_shapes_not_object():
    # The signatures that help() prints: every array parameter names its dtype and shape.
    for name in ("add_mesh", "deform_object", "add_group", "add_instance", "set_transform", "cast_rays",
                 "test_occlusions", "list_intersections", "compute_closest_points"):
        first = getattr(duplex.Scene, name).__doc__.splitlines()[0]
        params = split_top_level(first[first.index("(") + 1:first.rindex(") ->")])
        plain = [p for p in params if p.split("=")[0].split(":", 1)[1].strip() == "object"]
        assert not plain, f"Scene.{name}: {plain} shown as a plain object"
    assert "(..., 6) | (..., 8)" in duplex.Scene.cast_rays.__doc__.splitlines()[0]
