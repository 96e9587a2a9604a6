#!/usr/bin/env python3
"""Names the WebAssembly functions V8 compiled around the app's first and second merge.

    python3 tools/wasm_compiles.py P.trace.json MODULE.wasm P.log [--all]

P.trace.json and P.log come from `profile.mjs --trace --no-cpu --out P` run with
`SKYDOME_CHROMIUM_FLAGS=--js-flags=--trace-wasm-compilation-times DEBUG=pw:browser` (V8 prints
one line per compiled function, with its index, to the renderer's stdout, which playwright's
debug log copies). MODULE.wasm is the module the page ran (pkg-mt/ for the threaded core); its
name section gives the names. Prints, per merge, the functions optimised (TurboFan) during it,
with when the compile started and ended (ms from the merge's start) and how long it took, and
the count and time of lazy baseline (Liftoff) compiles; --all also lists those before the
first merge (the warm-up's). V8 compiles optimised code on background threads, in order of
completion; the trace's compile spans on those threads, sorted by end, are matched in order
with the log's TurboFan lines (their durations agree; the script prints both).
"""
import json
import re
import sys


def function_names(path):
    """Function index -> name, from the module's `name` custom section."""
    d = open(path, 'rb').read()

    def leb(i):
        r = s = 0
        while True:
            b = d[i]
            i += 1
            r |= (b & 0x7F) << s
            s += 7
            if b < 0x80:
                return r, i

    names, i = {}, 8
    while i < len(d):
        sid = d[i]
        n, i = leb(i + 1)
        end = i + n
        if sid == 0:
            ln, j = leb(i)
            if d[j:j + ln] == b'name':
                j += ln
                while j < end:
                    sub = d[j]
                    sz, j = leb(j + 1)
                    subend = j + sz
                    if sub == 1:
                        cnt, j = leb(j)
                        for _ in range(cnt):
                            idx, j = leb(j)
                            nl, j = leb(j)
                            names[idx] = d[j:j + nl].decode('utf8', 'replace')
                            j += nl
                    j = subend
        i = end
    return names


def main():
    trace, wasm, log = sys.argv[1:4]
    everything = '--all' in sys.argv
    names = function_names(wasm)
    short = lambda n: re.sub(r'\[[0-9a-f]{16}\]', '', n)[:140]
    ev = json.load(open(trace))
    marks = {e['args']['data']['message']: e['ts'] for e in ev
             if e.get('name') == 'TimeStamp' and 'data' in e.get('args', {})}
    windows = [('first', marks['skydome-first-start'], marks['skydome-first-end']),
               ('between', marks['skydome-first-end'], marks['skydome-second-start']),
               ('second', marks['skydome-second-start'], marks['skydome-second-end'])]

    def window(ts):
        for name, a, b in windows:
            if a <= ts < b:
                return name, a
        return ('before', windows[0][1]) if ts < windows[0][1] else ('after', windows[2][2])

    # Optimising compiles: V8.WasmInitializing ... V8.TFAssembleCode on one thread.
    spans, open_at = [], {}
    for e in sorted(ev, key=lambda e: e.get('ts', 0)):
        k = (e.get('pid'), e.get('tid'))
        if e.get('name') == 'V8.WasmInitializing':
            open_at[k] = e['ts']
        elif e.get('name') == 'V8.TFAssembleCode' and k in open_at:
            spans.append((open_at.pop(k), e['ts'] + e.get('dur', 0)))
    spans.sort(key=lambda s: s[1])
    lines = []
    for line in open(log, errors='replace'):
        m = re.search(r'Compiled function \S+#(\d+) using TurboFan, took (\d+) (ms|μs)', line)
        if m:
            lines.append((int(m.group(1)), int(m.group(2)) / (1 if m.group(3) == 'ms' else 1000)))
    print(f'{len(spans)} optimising compiles in the trace, {len(lines)} in the log')
    totals = {}
    for (fi, ms), (a, b) in zip(lines, spans):
        w, origin = window(a)
        t = totals.setdefault(w, [0, 0.0])
        t[0] += 1
        t[1] += ms
        if w != 'before' or everything:
            print(f'{w:8s} {(a - origin) / 1000:+7.0f} → {(b - origin) / 1000:+7.0f} ms  '
                  f'TurboFan {ms:6.1f} ms (trace {(b - a) / 1000:6.1f})  #{fi} {short(names.get(fi, "?"))}')
    for w, (n, ms) in totals.items():
        print(f'optimised {w}: {n} functions, {ms:.0f} ms of compiling')
    for name, a, b in windows:
        lazy = [e for e in ev if e.get('name') == 'wasm.CompileLazy' and a <= e['ts'] < b]
        print(f'lazy baseline compiles during {name}: {len(lazy)}, '
              f'{sum(e.get("dur", 0) for e in lazy) / 1000:.1f} ms')


if __name__ == '__main__':
    main()
