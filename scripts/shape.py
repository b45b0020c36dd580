#!/usr/bin/env python3
"""The code's shape, counted the same way every time: file and function sizes, the swarm
machine's per-vehicle bookkeeping, where sharding branches, and which subcommands import
each other. `python3 scripts/shape.py` prints a table; `--list` names the long files and
functions as well.

Definitions (so that two counts compare):
- a line of code is a non-blank line that is not only a `//` comment, in the library
  crates' sources (src, core/src, sitl/src, wire/src), the unit-test block at a file's
  end (`#[cfg(test)] mod tests`) and files named tests*.rs left out;
- a function runs from its `fn` line to the closing brace at the same indentation
  (rustfmt's layout), counted in raw lines;
- a method takes a bare vehicle index when a parameter is `i: usize`, `vehicle: usize` or
  `index: usize`;
- a sharding branch site is a line of core/src/swarm (tests out) that asks `is_remote`,
  `is_local`, or reaches `peers`.
"""
import os, re, sys

ROOTS = ['src', 'core/src', 'sitl/src', 'wire/src']
HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')


def sources(roots=ROOTS):
    for root in roots:
        for d, _, fs in os.walk(os.path.join(HERE, root)):
            for f in sorted(fs):
                if f.endswith('.rs') and not f.startswith('tests'):
                    yield os.path.relpath(os.path.join(d, f), HERE)


def without_tests(text):
    i = text.find('#[cfg(test)]\nmod tests')
    return text if i < 0 else text[:i]


def code_lines(text):
    return sum(1 for l in text.split('\n') if l.strip() and not l.strip().startswith('//'))


FN = re.compile(r'^(\s*)(?:pub(?:\([^)]*\))?\s+)?(?:const\s+)?(?:async\s+)?(?:unsafe\s+)?fn\s+(\w+)')


def functions(text):
    lines = text.split('\n')
    for k, l in enumerate(lines):
        m = FN.match(l)
        if not m:
            continue
        indent = m.group(1)
        # a declaration without a body (trait method) ends in `;` before any `{`
        j = k
        while j < len(lines) and '{' not in lines[j] and not lines[j].rstrip().endswith(';'):
            j += 1
        if j >= len(lines) or '{' not in lines[j]:
            continue
        if lines[j].rstrip().endswith('}'):
            yield m.group(2), 1 + j - k
            continue
        end = next((e for e in range(j + 1, len(lines)) if lines[e] == indent + '}'), None)
        if end is not None:
            yield m.group(2), end - k + 1


def struct_fields(text, name):
    m = re.search(r'^(?:pub(?:\([^)]*\))? )?struct ' + name + r'\b[^{;]*\{\n(.*?)\n\}', text, re.S | re.M)
    if not m:
        return []
    return [l for l in m.group(1).split('\n') if re.match(r'\s{4}(pub(\([^)]*\))? )?\w+: ', l)]


def main():
    listing = '--list' in sys.argv
    files = {f: without_tests(open(os.path.join(HERE, f)).read()) for f in sources()}
    loc = {f: code_lines(t) for f, t in files.items()}
    fns = [(n, f, name) for f, t in files.items() for name, n in functions(t)]
    rows = []
    rows.append(('lines of code (library crates, unit tests out)', sum(loc.values())))
    rows.append(('files', len(loc)))
    rows.append(('files over 400 lines of code', sum(v > 400 for v in loc.values())))
    rows.append(('files over 600 lines of code', sum(v > 600 for v in loc.values())))
    rows.append(('functions over 80 lines', sum(n > 80 for n, _, _ in fns)))
    rows.append(('functions over 100 lines', sum(n > 100 for n, _, _ in fns)))
    core = {f: t for f, t in files.items() if f.startswith('core/')}
    swarm_text = ''.join(t for f, t in core.items() if f.startswith('core/src/swarm/'))
    swarm_fields = struct_fields(files.get('core/src/swarm/mod.rs', ''), 'Swarm')
    rows.append(('fields of Swarm', len(swarm_fields)))
    per_vehicle = 0
    for f, t in core.items():
        if not f.startswith('core/src/swarm/'):
            continue
        for s in re.findall(r'(?:pub(?:\([^)]*\))? )?struct (\w+)', t):
            if s in ('Swarm',) or s.endswith('Arrays') or s in ('SafetyWork', 'Peers', 'VehicleSlot'):
                per_vehicle += sum(1 for l in struct_fields(t, s) if re.search(r':\s*Vec<', l))
    rows.append(('Vec fields of Swarm, its law arrays, SafetyWork, Peers, VehicleSlot', per_vehicle))
    bare = sum(len(re.findall(r'fn \w+(?:<[^>]*>)?\([^)]*\b(?:i|vehicle|index): usize', t, re.S))
               for t in core.values())
    rows.append(('core functions taking a bare vehicle index', bare))
    impl_files = [f for f, t in core.items() if re.search(r'^impl Swarm \{', t, re.M)]
    only_impl = [f for f in impl_files
                 if not re.search(r'^(pub(\([^)]*\))? )?(struct|enum|trait) ', files[f], re.M)]
    rows.append(("files with an `impl Swarm` block", len(impl_files)))
    rows.append(("  of which define no type of their own", len(only_impl)))
    sitl_impl = [f for f, t in files.items() if f.startswith('sitl/') and re.search(r'^impl Vehicle \{', t, re.M)]
    rows.append(("sitl files with an `impl Vehicle` block", len(sitl_impl)))
    vehicle_fields = struct_fields(files.get('sitl/src/autopilot/mod.rs', ''), 'Vehicle')
    rows.append(("fields of the emulator's Vehicle", len(vehicle_fields)))
    shard = sum(len(re.findall(r'is_remote\(|is_local\(|\bpeers\b', l))
                for f, t in core.items() if f.startswith('core/src/swarm/')
                for l in t.split('\n') if not l.strip().startswith('//'))
    rows.append(('sharding branch sites in core/src/swarm', shard))
    # A subcommand is src/cmd/X.rs or the directory src/cmd/X/; it imports another when it
    # names a sibling subcommand, through crate::cmd:: or (from its top file) super::.
    cmd_files = [f for f in files if f.startswith('src/cmd/')]
    subcommands = {f.split('/')[2].removesuffix('.rs') for f in cmd_files} - {'mod'}
    cmd_imports = 0
    for f in cmd_files:
        parts = f.split('/')
        me = parts[2].removesuffix('.rs')
        top = len(parts) == 3 or parts[3] == 'mod.rs'
        pattern = r'(?:crate::cmd|super)::(\w+)' if top else r'crate::cmd::(\w+)'
        named = set(re.findall(pattern, files[f])) & subcommands
        cmd_imports += len(named - {me})
    rows.append(('subcommand modules importing another subcommand', cmd_imports))
    width = max(len(r[0]) for r in rows)
    print(f"| {'measure'.ljust(width)} | value |")
    print(f"|{'-' * (width + 2)}|-------|")
    for name, value in rows:
        print(f'| {name.ljust(width)} | {value} |')
    if listing:
        print('\nfiles over 400 lines of code:')
        for f, v in sorted(loc.items(), key=lambda x: -x[1]):
            if v > 400:
                print(f'  {v:5}  {f}')
        print('\nfunctions over 80 lines:')
        for n, f, name in sorted(fns, reverse=True):
            if n > 80:
                print(f'  {n:5}  {f}: {name}')


if __name__ == '__main__':
    main()
