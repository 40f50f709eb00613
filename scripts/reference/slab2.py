from slab import *
import slab
def quadrature_sq(N, n, na, nb):
    """like slab.quadrature but on each interval above a critical cosine use mu = c + (b-c) t^2
    to remove the sqrt singularity of the Fresnel transmissivity at the critical angle"""
    cuts = []
    for nn in (na, nb):
        if nn < n:
            cuts.append(np.sqrt(1-(nn/n)**2))
    cuts = sorted(set([c for c in cuts if 0 < c < 1]))
    edges = [0.0] + cuts + [1.0]
    nint = len(edges)-1
    m = N//nint
    mus, ws = [], []
    for k in range(nint):
        lo, hi = edges[k], edges[k+1]
        last = (k == nint-1)
        mm = N-m*(nint-1) if last else m
        t, wt = (radau_right(mm, 0.0, 1.0) if last else gauss(mm, 0.0, 1.0))
        if k == 0:
            x = lo + (hi-lo)*t; w = wt*(hi-lo)
        else:   # sqrt-type behaviour at left end (a critical cosine)
            x = lo + (hi-lo)*t**2; w = wt*(hi-lo)*2*t
        mus.append(x); ws.append(w)
    return np.concatenate(mus), np.concatenate(ws), m
def mcml_slab2(mua, mus, g, d, n=1.0, na=1.0, nb=1.0, N=32, K=None):
    old = slab.quadrature
    slab.quadrature = quadrature_sq
    try:
        return slab.mcml_slab(mua, mus, g, d, n, na, nb, N, K)
    finally:
        slab.quadrature = old
