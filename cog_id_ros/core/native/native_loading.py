"""Loading a cached library of compiled kernels: what is loaded is what was checked.

The library is opened once (relative to the trusted cache directory, native_cache.py), its
owner, mode and size read from the open file, its bytes hashed and compared with the sha256
and the size recorded when it was built, its ELF headers checked to lie within the file (a
truncated library would crash the process with SIGBUS), and the loader is given that open
file (``/proc/<pid>/fd/<fd>``), not the name again, which another file could have taken
meanwhile.
"""
import hashlib
import importlib.machinery
import importlib.util
import json
import os
from types import ModuleType

from .native_build import elf_problem, library_suffix
from .native_cache import open_file, read_file


class Damaged(Exception):
    """A library that is not what was built (cut short, changed): not loaded."""


def load_cached(fd: int, directory: str, name: str, loaded: dict[tuple[int, int], int]
                ) -> tuple[ModuleType, dict[str, int], str] | None:
    """(module, operations, level) of the library ``name`` in the cache directory of
    descriptor ``fd``, the -O2 build before the -O0 one, or None when neither is there
    intact (it is then built again); Untrusted when a file of it may be another user's.
    ``loaded``: the descriptors this process keeps (:func:`load_verified`)."""
    text = read_file(fd, name + '.json', directory)
    try:
        operations = json.loads(text) if text is not None else None
    except ValueError:
        operations = None                     # damaged: built again
    if not isinstance(operations, dict):
        return None
    for level in ('O2', 'O0'):
        try:
            module = load_verified(fd, directory, name, level, loaded)
        except (Damaged, ImportError):
            continue                          # not what was built: built again
        if module is not None:
            return module, operations, level
    return None


def load_verified(fd: int, directory: str, name: str, level: str,
                  loaded: dict[tuple[int, int], int]) -> ModuleType | None:
    """The module of library ``name`` at ``level`` in the directory of descriptor ``fd``,
    None when it or its checksum is not there. The library is opened once: its bytes are
    hashed and compared with the sha256 and size recorded when it was built, its ELF headers
    checked to lie within them, and the loader loads that open file, not the name again
    (which another file could have taken meanwhile). Damaged when it is not what was built,
    ImportError when it will not load, Untrusted as :func:`open_file`. ``loaded``: (st_dev,
    st_ino) of every library this process loaded through its descriptor -> that descriptor,
    kept open for the life of the process (see :func:`_import_opened`)."""
    library = f'{name}.{level}{library_suffix()}'
    recorded = read_file(fd, library + '.sha256', directory)
    if recorded is None:
        return None
    opened, st = open_file(fd, library, directory)
    if opened is None or st is None:
        return None
    path = os.path.join(directory, library)
    try:
        data = _read_all(opened)
        try:
            digest, size_text = recorded.decode('ascii').split()
            size = int(size_text)
        except ValueError:                    # UnicodeDecodeError included
            raise Damaged(f'{path}.sha256 is not a checksum and a size') from None
        if not len(data) == st.st_size == size:
            raise Damaged(f'{path} has {len(data)} bytes, {size} when it was built')
        if hashlib.sha256(data).hexdigest() != digest:
            raise Damaged(f'{path} is not the library that was built (its sha256 differs)')
        problem = elf_problem(data)
        if problem:
            raise Damaged(f'{path}: {problem}')
    except BaseException:
        os.close(opened)
        raise
    return _import_opened(name, opened, st, path, loaded)


def _read_all(fd: int) -> bytes:
    chunks: list[bytes] = []
    while True:
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return b''.join(chunks)
        chunks.append(chunk)


def _import_opened(name: str, fd: int, st: os.stat_result, path: str,
                   loaded: dict[tuple[int, int], int]) -> ModuleType:
    """The module of the library open as ``fd`` (stat ``st``, verified); the descriptor is
    this function's to close or keep. The loader is given ``/proc/<pid>/fd/<fd>``: the very
    file that was verified, whatever has become of ``path`` since. That descriptor is never
    closed: the dynamic loader knows a library by the name it was given, and a later library
    opened under the same descriptor number (the same name) would be taken for the first
    one, loaded or not. Extension modules are never unloaded, so this costs a descriptor
    per library, which its mappings outlive anyway; the same file loaded again uses the
    descriptor kept for it (in ``loaded``). The pid in the name keeps a forked child's names
    apart from its parent's. Without /proc the library is loaded by its path if that is
    still the file that was verified."""
    through = f'/proc/{os.getpid()}/fd/{{}}'
    kept = loaded.get((st.st_dev, st.st_ino))
    if kept is not None and _same_file(through.format(kept), st):
        os.close(fd)
        return _import(name, through.format(kept))
    if _same_file(through.format(fd), st):
        loaded[(st.st_dev, st.st_ino)] = fd   # the loader's name for it from now on
        return _import(name, through.format(fd))
    try:
        if not _same_file(path, st):
            raise Damaged(f'{path} was replaced while it was being loaded')
        return _import(name, path)
    finally:
        os.close(fd)


def _same_file(path: str, st: os.stat_result) -> bool:
    try:
        here = os.stat(path)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (st.st_dev, st.st_ino)


def _import(name: str, path: str) -> ModuleType:
    loader = importlib.machinery.ExtensionFileLoader(name, path)
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    if spec is None:                          # never for an explicit loader; for the checker
        raise ImportError(f'{path} cannot be loaded as the module {name}')
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module
