"""Small rooms: no module of the package over MAX_FILE_LINES lines, no function over
MAX_FUNCTION_LINES (every def and async def: methods and nested functions too, counted from
its ``def`` line to its last line, docstring and comments included). A module that grows
past the bound is split into modules named after what they hold; a function, cut into its
steps. The offenders are printed, each with its size."""
import ast
import pathlib

PACKAGE = 'cog_id_ros'
ROOT = pathlib.Path(__file__).resolve().parent.parent / PACKAGE
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80


def package_files():
    """Every .py file of the package, as (path relative to the package, path)."""
    return sorted((path.relative_to(ROOT).as_posix(), path) for path in ROOT.rglob('*.py'))


def line_count(path):
    return len(path.read_text(encoding='utf-8').splitlines())


def functions(source, filename='<source>'):
    """(qualified name, first line, lines) of every function in the module ``source``."""
    tree = ast.parse(source, filename)
    found = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f'{prefix}{child.name}'
                found.append((name, child.lineno, child.end_lineno - child.lineno + 1))
                visit(child, f'{name}.')
            elif isinstance(child, ast.ClassDef):
                visit(child, f'{prefix}{child.name}.')
            else:
                visit(child, prefix)

    visit(tree, '')
    return found


def test_no_module_over_the_bound():
    over = [f'{name}: {lines} lines' for name, path in package_files()
            if (lines := line_count(path)) > MAX_FILE_LINES]
    print('\n'.join(over))
    assert over == [], f'modules over {MAX_FILE_LINES} lines:\n' + '\n'.join(over)


def test_no_function_over_the_bound():
    over = [f'{name}:{first} {function}: {lines} lines'
            for name, path in package_files()
            for function, first, lines in functions(path.read_text(encoding='utf-8'), str(path))
            if lines > MAX_FUNCTION_LINES]
    print('\n'.join(over))
    assert over == [], f'functions over {MAX_FUNCTION_LINES} lines:\n' + '\n'.join(over)


def test_the_counts_see_nested_functions_and_methods():
    source = ('class A:\n    def method(self):\n        def inner():\n            pass\n'
              '        return inner\n\n\nasync def coroutine():\n    pass\n')
    assert functions(source) == [('A.method', 2, 4), ('A.method.inner', 3, 2),
                                 ('coroutine', 8, 2)]
