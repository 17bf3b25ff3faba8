"""Every module, function and file the texts name exists: a module moved or a function renamed
leaves no stale name behind in the package's docstrings and comments, docs/*.md or README.md.

What counts as a reference (what these texts spell; anything else is prose):

* a dotted name that starts with ``cog_id_ros.`` (``cog_id_ros.ros.stop_signals``,
  ``cog_id_ros.core.errors.REASONS``), anywhere: imported and looked up;
* a path to a Python file (``core/solve/batch.py``, ``cog_id_ros/ros/node.py``, ``pipeline.py``):
  beside the text, in the package or in the repository (a bare file name anywhere there);
* in a docstring, a role (``:func:`name```, ``:meth:`Class.name```, ``:mod:`...```): looked
  up in the module, the class it is written in, or as an absolute name;
* a backticked ``module.name`` whose module is one of the package's, or ``Class.name`` of one
  of its classes (``pipeline.link_forces``, ``kernels.TRACE_BUDGET``,
  ``InverseDynamics.last_pose``): that module's attribute or an attribute of a class it
  defines, instance attributes included. ``mechanism.<name>`` and ``joints.<name>`` spell
  parameters (docs/mechanism.md), not modules, and are left alone; a name that is also a
  standard module's (``inspect.signature``) may be that module's.

A failure names the file and line of every reference that does not resolve.
"""
import ast
import dataclasses
import functools
import importlib
import inspect
import io
import os
import pkgutil
import re
import subprocess
import textwrap
import tokenize

import cog_id_ros

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(REPO, 'cog_id_ros')

#: first components that spell parameter names (mechanism.active_joints, joints.<name>.type)
PARAMETER_NAMESPACES = {'mechanism', 'joints'}
#: a backticked name ending so is a file, not a module's attribute (importing `setup` to
#: look up `cfg` would run the package's setup.py)
FILE_SUFFIXES = {'py', 'cfg', 'txt', 'md', 'yaml', 'yml', 'csv', 'urdf', 'png', 'c', 'h', 'so',
                 'json', 'toml', 'xml', 'sha256', 'lock', 'tmp'}

ABSOLUTE = re.compile(r'(?<![\w.])cog_id_ros(?:\.[A-Za-z_]\w*)+')
PATH = re.compile(r'(?<![\w./-])((?:[\w.-]+/)*\w+\.py)\b(?![\w/])')
ROLE = re.compile(r':(?:func|meth|class|mod|data|attr|exc|obj):`~?([\w.]+?)(?:\(\))?`')
BACKTICKED = re.compile(r'(?<!`)``?([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\(\))?``?(?!`)')


def texts():
    """(file relative to the repository, line, text, module name or None, class or None)
    of every docstring and comment of the package and every line of the docs."""
    for directory, _, files in os.walk(PACKAGE):
        for name in sorted(f for f in files if f.endswith('.py')):
            path = os.path.join(directory, name)
            module = os.path.relpath(path, REPO)[:-3].replace(os.sep, '.')
            module = module[:-len('.__init__')] if module.endswith('.__init__') else module
            yield from _python_texts(path, module)
    for path in [os.path.join(REPO, 'README.md')] + sorted(
            os.path.join(REPO, 'docs', f) for f in os.listdir(os.path.join(REPO, 'docs'))
            if f.endswith('.md')):
        with open(path, encoding='utf-8') as f:
            for line, text in enumerate(f, 1):
                yield os.path.relpath(path, REPO), line, text, None, None


def _python_texts(path, module):
    with open(path, encoding='utf-8') as f:
        source = f.read()
    rel = os.path.relpath(path, REPO)

    def visit(node, cls):
        body = getattr(node, 'body', [])
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            literal = ast.get_source_segment(source, body[0].value)   # lines as in the file
            for k, text in enumerate(literal.split('\n')):
                yield rel, body[0].value.lineno + k, text, module, cls
        for child in body:
            if isinstance(child, ast.ClassDef):
                yield from visit(child, child.name if cls is None else cls)
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield from visit(child, cls)

    yield from visit(ast.parse(source), None)
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield rel, token.start[0], token.string, module, None


@functools.lru_cache(maxsize=None)
def package_modules():
    """{last component: [module objects]} of every module of the package."""
    found = {}
    for info in pkgutil.walk_packages(cog_id_ros.__path__, 'cog_id_ros.'):
        module = importlib.import_module(info.name)
        found.setdefault(info.name.rsplit('.', 1)[-1], []).append(module)
    return found


@functools.lru_cache(maxsize=None)
def package_classes():
    """{name: [classes]} defined in the package."""
    found = {}
    for modules in package_modules().values():
        for module in modules:
            for name, value in vars(module).items():
                if inspect.isclass(value) and value.__module__ == module.__name__:
                    found.setdefault(name, []).append(value)
    return found


@functools.lru_cache(maxsize=None)
def instance_attributes(cls):
    """Names a class (or a base of it in the package) assigns as ``self.<name>``."""
    names = set()
    for klass in cls.__mro__:
        if not klass.__module__.startswith('cog_id_ros'):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and \
                    isinstance(node.value, ast.Name) and node.value.id == 'self':
                names.add(node.attr)
        if dataclasses.is_dataclass(klass):          # fields without a default
            names.update(field.name for field in dataclasses.fields(klass))
    return names


def has(obj, path):
    """``obj`` has the attributes ``path`` (a list of names), one inside the next."""
    for i, name in enumerate(path):
        if hasattr(obj, name):
            obj = getattr(obj, name)
        elif inspect.isclass(obj) and name in instance_attributes(obj):
            return i == len(path) - 1      # (what an instance attribute holds is not known)
        elif inspect.ismodule(obj):
            try:
                obj = importlib.import_module(f'{obj.__name__}.{name}')
            except ImportError:
                return False
        else:
            return False
    return True


def in_module(module, path):
    """``path`` in ``module``, or in a class the module defines."""
    if has(module, path):
        return True
    return any(has(value, path) for value in vars(module).values()
               if inspect.isclass(value) and value.__module__ == module.__name__)


def absolute(name):
    parts = name.split('.')
    return has(importlib.import_module(parts[0]), parts[1:])


@functools.lru_cache(maxsize=None)
def module_level_names():
    """{name: [full names]} of the functions, classes and constants the package's modules
    define (not methods: those names are too common to tell a stale module by)."""
    found = {}
    for modules in package_modules().values():
        for module in modules:
            tree = ast.parse(inspect.getsource(module))
            for node in tree.body:
                if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                    names = [node.name]
                elif isinstance(node, ast.Assign):
                    names = [t.id for t in node.targets if isinstance(t, ast.Name)]
                else:
                    continue
                for name in names:
                    if not name.startswith('__'):
                        found.setdefault(name, []).append(f'{module.__name__}.{name}')
    return found


def short(name):
    """Whether a backticked ``a.b`` names something of the package: (is a reference,
    resolves). One whose ``a`` is no module of the package but whose ``b`` is a function,
    class or constant of one names a module that is gone (``ros_conversions.trajectory_process``
    for ``cog_id_ros.ros.conversions.trajectory_process``)."""
    first, *rest = name.split('.')
    if first in PARAMETER_NAMESPACES or rest[-1] in FILE_SUFFIXES:
        return False, True      # a parameter's name, or a file (`setup.cfg`): never imported
    modules = package_modules().get(first, [])
    classes = package_classes().get(first, [])
    if not modules and not classes:
        gone = len(rest) == 1 and first.islower() and rest[0] in module_level_names()
        try:
            importlib.import_module(first)         # a module of its own (os.path)
        except ImportError:
            return gone, not gone
        return False, True
    if any(in_module(m, rest) for m in modules) or any(has(c, rest) for c in classes):
        return True, True
    try:                                   # a standard module of the same name
        return True, has(importlib.import_module(first), rest)
    except ImportError:
        return True, False


def role(name, module, cls):
    """A role's target, looked up from the docstring's module (or a class of it) and class;
    ``.name``: in the module's package."""
    if name.startswith('cog_id_ros.'):
        return absolute(name)
    if name.startswith('.') and module is not None:
        # Sphinx's leading dot: the docstring's module, its package, then any module of the
        # package that has it (``:class:`.NodeConfig``` in ros/node.py is ros/config.py's)
        package = module if hasattr(importlib.import_module(module), '__path__') else \
            module.rsplit('.', 1)[0]
        path = name[1:].split('.')
        return (absolute(module + name) or absolute(package + name) or
                any(in_module(m, path) for ms in package_modules().values() for m in ms))
    path = name.split('.')
    if module is not None:
        here = importlib.import_module(module)
        if in_module(here, path) or (cls is not None and has(getattr(here, cls), path)):
            return True
    return short(name)[1] if len(path) > 1 else False


@functools.lru_cache(maxsize=None)
def repository_files():
    """The repository's files (relative paths): git's, or every file outside hidden and
    build folders where this is no git checkout."""
    try:
        listed = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard'],
                                cwd=REPO, capture_output=True, text=True, check=True).stdout
        return set(listed.split())
    except (OSError, subprocess.CalledProcessError):
        found = set()
        for directory, folders, files in os.walk(REPO):
            folders[:] = [f for f in folders if not f.startswith('.') and f != 'build']
            found.update(os.path.relpath(os.path.join(directory, f), REPO) for f in files)
        return found


def path_exists(path, text_file):
    """A .py path named in ``text_file``: beside it, in the package or the repository."""
    files = repository_files()
    if '/' not in path:
        return any(os.path.basename(f) == path for f in files)
    here = os.path.dirname(text_file)
    return any(os.path.normpath(os.path.join(base, path)) in files
               for base in ('', 'cog_id_ros', here, os.path.dirname(here)))


def stale():
    """Every reference that does not resolve: 'file:line: what (kind)'."""
    out = []
    for path, line, text, module, cls in texts():
        for match in ABSOLUTE.finditer(text):
            if not absolute(match.group(0)):
                out.append(f'{path}:{line}: {match.group(0)}' + _now(match.group(0)))
        for match in PATH.finditer(text):
            if not path_exists(match.group(1), path):
                out.append(f'{path}:{line}: {match.group(1)} (no such file)')
        roles = set()
        for match in ROLE.finditer(text):
            roles.add(match.group(1))
            if not match.group(1).startswith('cog_id_ros.') and \
                    not role(match.group(1), module, cls):
                out.append(f'{path}:{line}: {match.group(0)}')
        for match in BACKTICKED.finditer(text):
            name = match.group(1)
            if name in roles or name.startswith('cog_id_ros.') or name.endswith('.py'):
                continue
            is_reference, resolves = short(name)
            if is_reference and not resolves:
                out.append(f'{path}:{line}: `{name}`' + _now(name))
    return out


def _now(name):
    """' (now X?)' with what the last part of a stale ``name`` is now called in full."""
    last = name.rsplit('.', 1)[-1]
    where = [m.__name__ for m in package_modules().get(last, [])] + \
        module_level_names().get(last, [])
    return f' (now {" or ".join(where)}?)' if where else ''


def test_every_module_function_and_file_named_in_the_texts_exists():
    found = stale()
    assert not found, ('stale references (rename them to what exists now):\n' +
                       '\n'.join(found))
