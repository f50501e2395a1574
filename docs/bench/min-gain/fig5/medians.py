# Paired medians of a bench's overhead runs: per scene, each mode's CPU and gather time over the
# unguided run of the same repeat (median, range) and its guided share.   medians.py OUT SCENE...
import csv,sys,statistics as st,collections
for s in sys.argv[2:]:
    rows=list(csv.DictReader(open(f'{sys.argv[1]}/{s}/overhead.csv')))
    by=collections.defaultdict(dict)
    for r in rows: by[int(r['repeat'])][r['guiding']]=r
    out=[]
    for mode in ['coherent','naive','grid']:
        cpu=[float(v[mode]['cpu_s'])/float(v['off']['cpu_s']) for v in by.values() if mode in v]
        g=[float(v[mode]['gather_s'])/float(v['off']['gather_s']) for v in by.values() if mode in v]
        frac=st.mean(float(v[mode]['guided_fraction']) for v in by.values() if mode in v)
        out.append(f"{mode} cpu {st.median(cpu):.3f} [{min(cpu):.2f}-{max(cpu):.2f}] gather {st.median(g):.3f} guided {100*frac:.0f}%")
    print(s, ' | '.join(out))
