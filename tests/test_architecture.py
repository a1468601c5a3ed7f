"""The layers of docs/design.md, "Layers", held against the code: imports point down the layer list, no import cycles
(lazy imports included), no module over 400 lines, no function over 8 parameters."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("hil", "drivers", "emulators")
MAX_LINES = 400
MAX_PARAMETERS = 8  # self and cls not counted; more are grouped in the small settings each stage uses
# docs/design.md, "Layers": an import may only point to its own layer or one above it in this list
LAYERS = (
    ("hil.config_types", "hil.inputs", "hil.units", "hil.samples", "hil.vocabulary"),
    ("drivers",),
    ("hil.config", "hil.config_emulated", "hil.config_environment", "hil.config_ratetests", "hil.config_units",
     "hil.frames"),
    ("hil.estimation",),
    ("emulators",),
    ("hil.pipeline", "hil.recording"),
    ("hil.outputs", "hil.viewer"),
    ("hil.trial",),
    ("hil.campaign", "hil.history"),
    ("hil.arguments", "hil.cli", "hil.commands", "hil.pytest_plugin", "hil.plan", "hil.ratetest_command"),
)


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(path: Path, modules: dict[str, Path]) -> set[str]:
    """Our modules that ``path`` imports anywhere (module level or inside functions)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name and name not in PACKAGES:
                found.add(name)
    return found


def _layer(module: str) -> int:
    for k, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return k
    raise AssertionError(f"{module} is in no layer of docs/design.md's list")


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(path, modules) - {name} for name, path in modules.items() if name not in PACKAGES}


def test_every_import_points_down_the_layer_list():
    wrong = [f"{a} (layer {_layer(a) + 1}) imports {b} (layer {_layer(b) + 1})"
             for a, targets in _graph().items() for b in sorted(targets) if _layer(b) > _layer(a)]
    assert not wrong, "\n".join(wrong)


def test_no_import_cycles():
    graph = _graph()
    state: dict[str, int] = {}  # 1 on the path, 2 done
    cycles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(path[path.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not cycles, "\n".join(cycles)


def test_no_module_is_over_400_lines():
    long = {name: n for name, path in _modules().items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_the_walk_sees_the_imports_it_checks():
    graph = _graph()
    assert "hil.pipeline.processor" in graph["hil.trial.live"]
    assert "drivers.decoder" in graph["hil.pipeline.decoding"]
    assert "hil.trial.offline" in graph["hil.commands.trials"]  # an import inside a function counts




def test_classes_of_the_data_flow_stay_small():
    """No class over 200 lines in hil/pipeline and hil/trial."""
    for path in sorted((ROOT / "hil" / "pipeline").glob("*.py")) + sorted((ROOT / "hil" / "trial").glob("*.py")):
        name = str(path.relative_to(ROOT))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                lines = node.end_lineno - node.lineno + 1
                assert lines <= 200, f"{name}: {node.name} has {lines} lines"


def _parameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """How many parameters ``function`` takes: positional, keyword-only, ``*args`` and ``**kwargs``, its first one
    not counted when it is ``self`` or ``cls``."""
    args = function.args
    positional = args.posonlyargs + args.args
    bound = bool(positional) and positional[0].arg in ("self", "cls")
    return len(positional) - bound + len(args.kwonlyargs) + (args.vararg is not None) + (args.kwarg is not None)


def _over_parameters(tree: ast.AST) -> dict[str, int]:
    """Each function or method of ``tree`` over ``MAX_PARAMETERS`` parameters: its name, how many."""
    return {node.name: n for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and (n := _parameters(node)) > MAX_PARAMETERS}


def test_no_function_takes_more_than_8_parameters():
    """hil/, drivers/ and emulators/: no function, method or constructor over 8 parameters."""
    paths = [path for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))]
    over = {f"{path.relative_to(ROOT)}::{name}": n for path in paths
            for name, n in _over_parameters(ast.parse(path.read_text())).items()}
    assert not over, f"over {MAX_PARAMETERS} parameters: {over}"


def test_the_parameter_count_leaves_out_self_and_counts_the_rest():
    source = ("def nine(a, b, c, d, e, f, g, h, i): pass\n"
              "class C:\n"
              "    def __init__(self, a, b, c, d, e, f, g, h): pass\n"
              "    @classmethod\n"
              "    def make(cls, a, *rest, b, c, d, e, f, g, **options): pass\n"
              "    async def run(self, a, /, b, c, d, e, f, g, h, *, i): pass\n")
    assert _over_parameters(ast.parse(source)) == {"nine": 9, "make": 9, "run": 9}


PIPELINE_CALLS = {"feed", "feed_batch", "skip", "finish", "finished"}  # the rest comes out as Progress and Finished


def _pipeline_reads(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, attribute) of every read of a TrialProcessor's attribute other than its calls in ``tree``: names and
    attributes assigned a ``TrialProcessor(...)`` are the processors."""
    made = [node for node in ast.walk(tree) if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
            and getattr(node.value.func, "id", "") == "TrialProcessor"]
    held = {getattr(target, "id", None) or getattr(target, "attr", None) for node in made for target in node.targets}
    return [(node.lineno, node.attr) for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and node.attr not in PIPELINE_CALLS
            and (getattr(node.value, "id", None) in held or getattr(node.value, "attr", None) in held)]


def test_nobody_reads_the_pipeline_but_through_what_it_publishes():
    """Outside hil/pipeline, a TrialProcessor is fed and finished; what it did is read from the Progress and the
    Finished it returns, never from its attributes or its stages."""
    wrong = [f"{path.relative_to(ROOT)}:{line}: .{attr}"
             for path in [p for package in ("hil", "tests", "benchmarks") for p in (ROOT / package).rglob("*.py")]
             if path.parent.name != "pipeline" for line, attr in _pipeline_reads(ast.parse(path.read_text()))]
    assert not wrong, "\n".join(wrong)


def test_the_pipeline_check_finds_a_read_of_an_attribute():
    source = ("processor = TrialProcessor(cfg)\nprocessor.feed(item)\nn = processor.updates\n"
              "self.p = TrialProcessor(cfg)\nself.p.finish()\nself.p.estimation.estimator\n")
    assert sorted(attr for _, attr in _pipeline_reads(ast.parse(source))) == ["estimation", "updates"]
