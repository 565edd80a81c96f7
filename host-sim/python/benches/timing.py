"""Medians of 21 calls of the numpy API on one phantom folder (`ribreg phantom --out-dir DIR`).

Usage: python host-sim/python/benches/timing.py DIR
"""
import statistics, sys, time
import ribreg
d = sys.argv[1]
t, l = ribreg.read_cloud(f"{d}/template.ply"); g, _ = ribreg.read_cloud(f"{d}/target.ply")
w, _ = ribreg.read_waypoints(f"{d}/waypoints.csv")
def med(f, n=21):
    xs = []
    for _ in range(n):
        t0 = time.perf_counter(); f(); xs.append(time.perf_counter() - t0)
    return statistics.median(xs) * 1e3
tpl = ribreg.Template(t, l)
print(f"Template(points, labels): {med(lambda: ribreg.Template(t, l)):.1f} ms")
print(f"register(points, target, labels): {med(lambda: ribreg.register(t, g, l)):.1f} ms")
print(f"register(prepared Template, target): {med(lambda: ribreg.register(tpl, g)):.1f} ms")
r = ribreg.register(tpl, g)
print(f"transform(10 waypoints): {med(lambda: r.transform(w)):.2f} ms")
