#!/usr/bin/env python3
"""Import circles between modules of each crate: top-level modules, and sibling modules
within one directory (a parent mod.rs using its children is not an edge)."""
import os, re, sys, itertools, collections
roots = {'ringswarm': 'src', 'ringswarm-core': 'core/src', 'ringswarm-sitl': 'sitl/src', 'ringswarm-wire': 'wire/src'}
def modpath(root, f):
    rel = os.path.relpath(f, root)[:-3].split(os.sep)
    if rel[-1] in ('mod', 'lib', 'main'): rel = rel[:-1]
    return rel
def strip_tests(text):
    # drop #[cfg(test)] mod tests { ... } blocks crudely: from the attribute to the end
    i = text.find('#[cfg(test)]\nmod tests')
    return text if i < 0 else text[:i]
found = False
for crate, root in roots.items():
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', root)
    files = [os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs if f.endswith('.rs')]
    edges = collections.defaultdict(set)
    for f in files:
        if os.path.basename(f).startswith('tests'): continue
        me = modpath(root, f)
        text = strip_tests(open(f).read())
        text = re.sub(r'//[^\n]*', '', text)
        for m in re.finditer(r'\b(crate|super)((?:::[a-z_][a-z0-9_]*)+)', text):
            segs = m.group(2).split('::')[1:]
            if m.group(1) == 'crate':
                target = segs
            else:
                base = me[:-1] if not f.endswith('mod.rs') else me[:-1]
                # `super` from a file module a/b.rs is module a; from a/b/mod.rs it is a
                target = base + segs
            # resolve to the longest existing module prefix
            for n in range(len(target), 0, -1):
                cand = target[:n]
                if any(modpath(root, g) == cand for g in files):
                    target = cand; break
            else:
                continue
            # top-level edge
            if me and target and me[0] != target[0]:
                edges[('top', me[0])].add(('top', target[0]))
            # sibling edge (same parent, neither an ancestor of the other)
            k = 0
            while k < min(len(me), len(target)) and me[k] == target[k]: k += 1
            if k < len(me) and k < len(target):
                a, b = tuple(me[:k+1]), tuple(target[:k+1])
                if a != b: edges[('sib', a)].add(('sib', b))
    # cycles: strongly connected components
    index = {}; low = {}; stack = []; on = set(); sccs = []; counter = [0]
    nodes = set(edges) | {t for ts in edges.values() for t in ts}
    sys.setrecursionlimit(10000)
    def strong(v):
        index[v] = low[v] = counter[0]; counter[0] += 1; stack.append(v); on.add(v)
        for w in edges.get(v, ()):
            if w not in index: strong(w); low[v] = min(low[v], low[w])
            elif w in on: low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: sccs.append(comp)
    for v in nodes:
        if v not in index: strong(v)
    for comp in sccs:
        found = True
        print(crate, ' <-> '.join('::'.join(c[1]) if c[0]=='sib' else c[1] for c in comp))
if not found:
    print("no import circle")
else:
    sys.exit(1)
