#!/usr/bin/env python3
"""check_unity_clash.py BUILD_DIR: fails (one line per clash) when two .cpp files of one
unity target define the same file-local name in the same namespace.

With SHADOWTILE_UNITY a target's .cpp files are compiled in batches (CMake writes each
batch as CMakeFiles/<target>.dir/Unity/unity_<n>_<lang>.cxx, a list of #includes). A
file-local name (anything in an anonymous namespace, a `static` function or variable, a
const variable at namespace scope) defined by two files of a target becomes a
redefinition, or a silent overload, as soon as a batch holds both; which files share a
batch changes whenever a file is added. So the check is per target, over every file of
all its batches: a clash is caught here, cheaply, not by a broken build later. Files
compiled alone (SKIP_UNITY_BUILD_INCLUSION) are in no batch and not checked.

The scan reads the sources as text (comments, strings and preprocessor lines dropped;
braces tracked for namespaces): names declared at namespace scope only, never inside a
class or function. Stdlib only, a few seconds for the whole tree."""
import collections
import glob
import os
import re
import sys

TOKEN = re.compile(r'[A-Za-z_]\w*|::|\[\[|\]\]|[{}();<>=\[\],:*&~]|\S')
IDENT = re.compile(r'[A-Za-z_]\w*$')
KEYWORDS = {'static_assert', 'return', 'if', 'for', 'while', 'switch', 'sizeof', 'decltype', 'alignas', 'noexcept'}
SPECIFIERS = {'static', 'inline', 'constexpr', 'const', 'extern', 'thread_local', 'constinit', 'consteval', 'volatile',
              'unsigned', 'signed', 'mutable', 'typename'}


def strip(text):
    """Comments, string and character literals, and preprocessor lines removed."""
    out = []
    i, n = 0, len(text)
    line_start = True
    while i < n:
        c = text[i]
        if line_start and c == '#':  # a directive, with its continuation lines
            while i < n and text[i] != '\n':
                i += 2 if text[i] == '\\' and i + 1 < n else 1
            continue
        if c == '/' and text.startswith('//', i):
            i = text.find('\n', i)
            i = n if i < 0 else i
            continue
        if c == '/' and text.startswith('/*', i):
            j = text.find('*/', i + 2)
            i = n if j < 0 else j + 2
            out.append(' ')
            continue
        m = re.match(r'(?:u8|u|U|L)?R"([^(\s]*)\(', text[i:i + 24]) if c in 'RuUL' else None
        if m and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == '_')):
            end = text.find(')' + m.group(1) + '"', i + m.end())
            i = n if end < 0 else end + len(m.group(1)) + 2
            out.append('""')
            continue
        if c in '"\'':
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator (1'000)
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != '\n':
                j += 2 if text[j] == '\\' else 1
            i = j + 1
            out.append('""')
            continue
        if c == '\n':
            line_start = True
        elif not c.isspace():
            line_start = False
        out.append(c)
        i += 1
    return ''.join(out)


def top_level(tokens, wanted):
    """Index of the first token in `wanted` outside (), [] and <> (-1: none)."""
    depth = 0
    for i, t in enumerate(tokens):
        if depth == 0 and t in wanted:
            return i
        if t in '([<':
            depth += 1
        elif t in ')]>' and depth > 0:
            depth -= 1
    return -1


def declared(stmt, anonymous):
    """(name, file_local) for a namespace-scope statement, or None."""
    t = list(stmt)
    while t and t[0] == 'template':  # template <...>
        i, depth = 1, 0
        while i < len(t):
            depth += t[i] == '<'
            depth -= t[i] == '>'
            i += 1
            if depth == 0:
                break
        t = t[i:]
    while t and t[0] == '[[':
        t = t[t.index(']]') + 1:] if ']]' in t else []
    if not t or t[0] in KEYWORDS or t[0] == 'namespace' or t[0] == 'friend':
        return None
    if re.fullmatch(r'[A-Z][A-Z0-9_]*', t[0]) and len(t) > 1 and t[1] == '(':
        return None  # a macro's invocation (TEST(...), ST_VK_CASE(...))
    specifiers = set()
    if t[0] == 'using':
        if len(t) > 2 and t[2] == '=' and IDENT.match(t[1]):
            return (t[1], 'alias ' + ' '.join(t[3:])) if anonymous else None
        return None
    if t[0] == 'typedef':
        names = [x for x in t if IDENT.match(x)]
        return (names[-1], 'alias ' + ' '.join(t[1:-1])) if anonymous and names else None
    k = 0
    while k < len(t) and t[k] in SPECIFIERS:
        specifiers.add(t[k])
        k += 1
    if k < len(t) and t[k] in ('struct', 'class', 'union', 'enum'):
        j = k + 1
        while j < len(t) and t[j] in ('class', 'struct', 'alignas', 'final'):
            j += 1
        if j < len(t) and IDENT.match(t[j]) and top_level(t[k:], {'(', '='}) == -1:
            # a definition (the caller passes statements ending in `{`) or a forward
            # declaration (ending in `;`: not counted, it defines nothing)
            return (t[j], anonymous) if stmt_defines(stmt) else None
    eq = top_level(t, {'=', '(', '{', '['})
    if eq <= 0:
        j = len(t) - 1  # `int x;`
        name = t[j] if j >= 0 and IDENT.match(t[j]) else None
        is_function = False
    else:
        name = t[eq - 1]
        is_function = t[eq] == '('
        if not IDENT.match(name) or name == 'operator' or (eq >= 2 and t[eq - 2] in ('::', 'operator', '~')):
            return None  # a member defined outside its class, an operator
    if not name or name in SPECIFIERS or len([x for x in t[:max(eq, 1)] if IDENT.match(x)]) < 2:
        return None  # no type before the name: not a declaration
    before = t[:eq] if eq > 0 else t[:-1]
    stars = [i for i, x in enumerate(before) if x in ('*', '&')]
    const_object = 'constexpr' in specifiers or 'const' in before[(stars[-1] if stars else 0):]  # not a pointer to const
    local = anonymous or 'static' in specifiers or (
        not is_function and const_object and 'inline' not in specifiers and 'extern' not in specifiers)
    return (name, True) if local else None


def stmt_defines(stmt):
    return getattr(stmt, 'ends_with_brace', False)


class Stmt(list):
    ends_with_brace = False


def file_local_names(path):
    """{(namespace, name): what} for the file-local names `path` defines at namespace scope;
    `what` is a type alias's "alias <type>" (the same alias in two files is no clash), else True."""
    with open(path, encoding='utf-8', errors='replace') as f:
        tokens = TOKEN.findall(strip(f.read()))
    names = {}
    scopes = []  # ('ns', name or None) or ('block', None)
    stmt = Stmt()
    for tok in tokens:
        at_ns = all(kind != 'block' for kind, _ in scopes)
        if tok == '{':
            if at_ns and stmt and stmt[0] == 'namespace':
                parts = [x for x in stmt[1:] if IDENT.match(x) and x != 'inline']
                if not parts:
                    scopes.append(('ns', None))
                else:
                    for p in parts:
                        scopes.append(('ns', p))
                    scopes.append(('ns-end', len(parts)))  # `namespace a::b {` closes as one
            elif at_ns and stmt and stmt[0] == 'extern' and len(stmt) <= 2:
                scopes.append(('ns', ''))  # extern "C" { (the string is gone)
            else:
                if at_ns and stmt:
                    stmt.ends_with_brace = True
                    d = declared(stmt, any(kind == 'ns' and name is None for kind, name in scopes))
                    if d and d[1]:
                        names[(ns_path(scopes), d[0])] = d[1]
                scopes.append(('block', None))
            stmt = Stmt()
        elif tok == '}':
            if scopes and scopes[-1][0] == 'ns-end':
                count = scopes.pop()[1]
                del scopes[len(scopes) - count:]
            elif scopes:
                scopes.pop()
            stmt = Stmt()
        elif tok == ';':
            if at_ns and stmt:
                d = declared(stmt, any(kind == 'ns' and name is None for kind, name in scopes))
                if d and d[1]:
                    names[(ns_path(scopes), d[0])] = d[1]
            stmt = Stmt()
        else:
            stmt.append(tok)
    return names


def ns_path(scopes):
    return '::'.join(name for kind, name in scopes if kind == 'ns' and name)


def targets(build_dir):
    """{target: [source files]} from the unity batch files under build_dir."""
    out = collections.defaultdict(list)
    for batch in sorted(glob.glob(os.path.join(build_dir, '**', 'CMakeFiles', '*.dir', 'Unity', 'unity_*.cxx'),
                                  recursive=True)):
        target = os.path.basename(os.path.dirname(os.path.dirname(batch)))[:-len('.dir')]
        with open(batch) as f:
            for inc in re.findall(r'#include\s+"([^"]+)"', f.read()):
                out[target].append(inc if os.path.isabs(inc) else os.path.normpath(os.path.join(os.path.dirname(batch), inc)))
    return out


def main():
    if len(sys.argv) != 2:
        sys.exit('usage: check_unity_clash.py BUILD_DIR')
    found = targets(sys.argv[1])
    if not found:
        sys.exit('check_unity_clash: no unity batches under ' + sys.argv[1] + ' (configure with SHADOWTILE_UNITY=ON)')
    clashes = 0
    files = 0
    for target, sources in sorted(found.items()):
        where = collections.defaultdict(list)
        what = collections.defaultdict(set)
        for src in sources:
            files += 1
            for key, kind in file_local_names(src).items():
                where[key].append(src)
                what[key].add(kind)
        for (ns, name), srcs in sorted(where.items()):
            same_alias = len(what[(ns, name)]) == 1 and str(next(iter(what[(ns, name)]))).startswith('alias ')
            if len(srcs) > 1 and not same_alias:
                clashes += 1
                print('unity clash in %s: %s%s is file-local in %s' % (
                    target, ns + '::' if ns else '', name, ', '.join(os.path.relpath(s) for s in srcs)))
    print('check_unity_clash: %d targets, %d files, %d clashes' % (len(found), files, clashes))
    sys.exit(1 if clashes else 0)


if __name__ == '__main__':
    main()
