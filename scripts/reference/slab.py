"""Independent discrete-ordinate slab solver (matrix-exponential start + doubling/adding),
normal-incidence pencil beam, HG phase function with delta-M, Fresnel boundaries with
semi-infinite ambient media above/below (MCML conventions). Scratch verification code."""
import numpy as np
from numpy.polynomial import legendre as L
from scipy.linalg import expm, solve

def gauss(m, a, b):
    x, w = L.leggauss(m)
    return a + (b-a)*(x+1)/2, w*(b-a)/2

def radau_right(m, a, b):
    """m-point Gauss-Radau on [a,b] including the right endpoint b."""
    if m == 1:
        return np.array([b]), np.array([b-a])
    # left-Radau on [-1,1]: nodes = -1 and roots of (P_{m-1}+P_m)/(1+x)
    c = np.zeros(m+1); c[m-1] = 1; c[m] = 1
    r = L.legroots(c)
    r = np.sort(r)
    # remove the -1 root
    idx = np.argmin(abs(r+1)); r = np.delete(r, idx)
    Pm1 = L.legval(r, np.eye(m)[m-1])
    wr = (1-r)/(m*m*Pm1**2)
    x = np.concatenate(([-1.0], r)); w = np.concatenate(([2.0/(m*m)], wr))
    # flip so endpoint is +1
    x = -x[::-1]; w = w[::-1]
    return a + (b-a)*(x+1)/2, w*(b-a)/2

def fresnel(n_i, n_t, mu_i):
    """unpolarized Fresnel reflectance for light going from n_i to n_t with cos(inc)=mu_i"""
    mu_i = np.asarray(mu_i, float)
    if n_i == n_t:
        return np.zeros_like(mu_i)
    s2 = (n_i/n_t)**2*(1-mu_i**2)
    R = np.ones_like(mu_i)
    ok = s2 < 1
    mt = np.sqrt(1-s2[ok]); mi = mu_i[ok]
    rs = (n_i*mi - n_t*mt)/(n_i*mi + n_t*mt)
    rp = (n_i*mt - n_t*mi)/(n_i*mt + n_t*mi)
    R[ok] = 0.5*(rs**2+rp**2)
    return R

def quadrature(N, n, na, nb):
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
        if k < nint-1:
            x, w = gauss(m, edges[k], edges[k+1])
        else:
            x, w = radau_right(N-m*(nint-1), edges[k], edges[k+1])
        mus.append(x); ws.append(w)
    return np.concatenate(mus), np.concatenate(ws), m

def phase_matrices(mu, g, K):
    f = g**K
    k = np.arange(K)
    chi = (g**k - f)/(1-f) if f < 1 else np.zeros(K)
    P = np.array([L.legval(mu, np.eye(K)[j]) for j in range(K)])   # K x N
    Pm = P*((-1.0)**k)[:, None]
    coef = 0.5*(2*k+1)*chi
    Pt = (P.T*coef) @ P       # p(mu_i, mu_j)
    Pr = (P.T*coef) @ Pm      # p(mu_i, -mu_j)
    return Pt, Pr, f

def slab_RT(mu, w, a, g, tau, K, renorm=True):
    """radiance reflection/transmission operators of a homogeneous slab (delta-M scaled)"""
    N = len(mu)
    Pt, Pr, f = phase_matrices(mu, g, K)
    if renorm:
        s = (Pt+Pr) @ w           # should be 1
        Pt = Pt/s[:, None]; Pr = Pr/s[:, None]
    astar = a*(1-f)/(1-a*f)
    tstar = tau*(1-a*f)
    W = np.diag(w); Mi = np.diag(1/mu); I = np.eye(N)
    A11 = Mi @ (-I + astar*Pt @ W)
    A12 = Mi @ (astar*Pr @ W)
    A = np.block([[A11, A12], [-A12, -A11]])
    if tstar == 0:
        return np.zeros((N, N)), I.copy()
    if np.isinf(tstar):
        k = 60; d = min(0.5*mu.min(), 0.01)
    else:
        d = tstar; k = 0
        while d > min(0.5*mu.min(), 0.01):
            d /= 2; k += 1
    Phi = expm(A*d)
    P11, P12, P21, P22 = Phi[:N, :N], Phi[:N, N:], Phi[N:, :N], Phi[N:, N:]
    R = -solve(P22, P21)
    T = P11 + P12 @ R
    for _ in range(k):   # doubling (homogeneous symmetric layer)
        X = solve(I - R @ R, T)      # (I - R R)^-1 T
        Rn = R + T @ R @ X
        Tn = T @ X
        R, T = Rn, Tn
        if np.isinf(tstar) and np.max(abs(T)) < 1e-300:
            break
    return R, T

def mcml_slab(mua, mus, g, d, n=1.0, na=1.0, nb=1.0, N=32, K=None):
    tau = (mua+mus)*d
    a = mus/(mua+mus) if mua+mus > 0 else 0.0
    mu, w, m = quadrature(N, n, na, nb)
    if K is None:
        K = 2*m   # moments integrable by the composite rule
    R, T = slab_RT(mu, w, a, g, tau, K)
    Ft = np.diag(fresnel(n, na, mu)); Fb = np.diag(fresnel(n, nb, mu))
    I = np.eye(len(mu))
    Rsp = ((na-n)/(na+n))**2
    iN = np.argmax(mu)                # mu = 1 node
    s = np.zeros(len(mu)); s[iN] = (1-Rsp)/(2*w[iN]*mu[iN])
    Rp = R + T @ Fb @ solve(I - R @ Fb, T)
    D = solve(I - Ft @ Rp, s)
    U = Rp @ D
    Db = solve(I - R @ Fb, T @ D)
    flux = 2*mu*w
    Rd = flux @ ((1-np.diag(Ft))*U)
    Tt = flux @ ((1-np.diag(Fb))*Db)
    return Rd, Tt, Rsp
