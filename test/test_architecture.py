"""The faces of the package on their floors: the core imports nothing of the package outside
core/ (it knows no file format, no ROS), and no module imports, however indirectly, a module
that imports it back. Read from the source (every import statement, at the top of a module
or inside a function: a lazy import is an import), not from what happens to be loaded."""
import ast
import os
import pathlib

PACKAGE = 'cog_id_ros'
ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), PACKAGE)


def package_modules():
    """{dotted module name: path} of every module of the package; a package is its
    __init__.py, named after the package."""
    modules = {}
    for folder, _, files in os.walk(ROOT):
        parts = [PACKAGE, *os.path.relpath(folder, ROOT).split(os.sep)]
        parts = [part for part in parts if part != '.']
        for file in files:
            if file.endswith('.py'):
                stem = file[:-3]
                name = '.'.join(parts if stem == '__init__' else [*parts, stem])
                modules[name] = os.path.join(folder, file)
    return modules


def imported(name, path, modules):
    """The package's modules that module ``name`` imports, anywhere in its source. ``from
    X import n`` imports X.n when that is a module, else X (its __init__)."""
    tree = ast.parse(pathlib.Path(path).read_text(encoding='utf-8'), path)
    is_package = path.endswith('__init__.py')
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                # the package a relative import starts from: its own for an __init__
                base = name.split('.')
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                source = '.'.join(base + ([node.module] if node.module else []))
            else:
                source = node.module
            targets = [f'{source}.{alias.name}' if f'{source}.{alias.name}' in modules
                       else source for alias in node.names]
        else:
            continue
        found.update(target for target in targets if target in modules)
    found.discard(name)
    return found


def import_graph():
    modules = package_modules()
    return {name: imported(name, path, modules) for name, path in modules.items()}


def test_the_graph_sees_every_kind_of_import():
    graph = import_graph()
    assert 'cog_id_ros.core.model.mechanism' in graph['cog_id_ros.core']           # from .x import
    assert 'cog_id_ros.core.closure.closure' in graph['cog_id_ros.core.model.mechanism']   # from . import x
    assert 'cog_id_ros.core' in graph['cog_id_ros.ros.node']                 # from ..core import
    assert 'cog_id_ros.ros.player' in graph['cog_id_ros.demos.fig4']          # in a function
    assert 'cog_id_ros' in graph['cog_id_ros.offline.console']               # import cog_id_ros


def test_core_imports_nothing_of_the_package_outside_core():
    outside = {name: sorted(target for target in targets
                            if target != 'cog_id_ros.core' and
                            not target.startswith('cog_id_ros.core.'))
               for name, targets in import_graph().items()
               if name == 'cog_id_ros.core' or name.startswith('cog_id_ros.core.')}
    assert {name: found for name, found in outside.items() if found} == {}


def test_no_import_cycle():
    graph = import_graph()
    state = {}          # module -> 'open' while its imports are walked, 'done' after

    def cycle_from(name, path):
        state[name] = 'open'
        for target in sorted(graph[name]):
            if state.get(target) == 'open':
                return path[path.index(target):] + [target]
            if target not in state:
                found = cycle_from(target, path + [target])
                if found:
                    return found
        state[name] = 'done'
        return None

    for name in sorted(graph):
        if name not in state:
            found = cycle_from(name, [name])
            assert found is None, 'import cycle: ' + ' -> '.join(found)


#: the concept folders of core/, in import order: a module of one imports only modules of
#: the folders before it, of its own folder, or of core/ itself (errors.py, value_types.py,
#: which import no folder); a folder not listed here is bound only by the cycle test
CORE_LAYERS = ['linalg', 'kinematics', 'closure', 'model', 'dynamics', 'native', 'solve',
               'transmission', 'simulation', 'api']


def core_folder(name):
    """The folder of core/ that module ``name`` is in ('' for core/ itself), or None."""
    parts = name.split('.')
    if parts[:2] != ['cog_id_ros', 'core']:
        return None
    inside = len(parts) > 2 and os.path.isdir(os.path.join(ROOT, 'core', parts[2]))
    return parts[2] if inside else ''


def test_core_folders_import_in_their_order():
    upward = []
    for name, targets in import_graph().items():
        folder = core_folder(name)
        if folder is None or name == 'cog_id_ros.core':
            continue        # (core/__init__.py re-exports from every folder)
        for target in sorted(targets):
            to = core_folder(target)
            if to is None or to == folder or to == '' and target != 'cog_id_ros.core':
                continue
            if folder == '' or to == '' or (folder in CORE_LAYERS and to in CORE_LAYERS and
                                             CORE_LAYERS.index(to) > CORE_LAYERS.index(folder)):
                upward.append(f'{name} -> {target}')
    assert upward == [], 'imports against the order of CORE_LAYERS:\n' + '\n'.join(upward)
