from slab2 import *
from math import pi, exp, inf
cases = [
 ("mcml_vdh", dict(mua=10,mus=90,g=0.75,d=0.02)),
 ("disort3a", dict(mua=0,mus=10,g=0.75,d=0.1)),
 ("disort3b", dict(mua=0,mus=80,g=0.75,d=0.1)),
 ("iad_a08_g0", dict(mua=2,mus=8,g=0.0,d=0.1)),
 ("iad_a08_g08", dict(mua=2,mus=8,g=0.8,d=0.1)),
 ("iad_a095_b2", dict(mua=1,mus=19,g=0.0,d=0.1)),
 ("iad_a099_b10", dict(mua=0.1,mus=9.9,g=0.0,d=1.0)),
 ("semiinf_a095_g0 d=1", dict(mua=5,mus=95,g=0.0,d=1.0)),
 ("semiinf_a095_g0 d=inf", dict(mua=5,mus=95,g=0.0,d=inf)),
 ("semiinf_a095_g09 d=5", dict(mua=5,mus=95,g=0.9,d=5.0)),
 ("semiinf_a095_g09 d=inf", dict(mua=5,mus=95,g=0.9,d=inf)),
 ("abs_n15", dict(mua=100,mus=0,g=0,d=0.01,n=1.5)),
 ("abs_n14_1_133", dict(mua=1,mus=0,g=0,d=1,n=1.4,na=1.0,nb=1.33)),
 ("abs_n133_1_15", dict(mua=2,mus=0,g=0,d=1,n=1.33,na=1.0,nb=1.5)),
 ("tir_n15_g0", dict(mua=10,mus=90,g=0.0,d=0.02,n=1.5)),
 ("back_gm05", dict(mua=10,mus=90,g=-0.5,d=0.02)),
 ("tir_n14_g09_mixed", dict(mua=1,mus=100,g=0.9,d=0.1,n=1.4,na=1.0,nb=1.33)),
 ("thick_conservative_g09_n15", dict(mua=0,mus=200,g=0.9,d=0.1,n=1.5)),
 ("thick_backward_gm05_n133", dict(mua=0.1,mus=199.9,g=-0.5,d=0.1,n=1.33)),
]
for name, kw in cases:
    res = []
    for N in (32, 64, 96):
        Rd, Tt, Rsp = mcml_slab2(N=N, **kw)
        res.append((Rd, Tt))
    print("%-24s Rsp=%.6f  " % (name, Rsp) + "  ".join("N%d: %.7f %.7f" % (N, r[0], r[1]) for N, r in zip((32,64,96), res)))
print("DISORT 3a: Rd=%.7f Tt=%.7f" % (0.247374/pi, (1.15573+1.73849)/pi))
print("DISORT 3b: Rd=%.7f Tt=%.7f" % (1.59096/pi, (1.05389e-3+1.54958)/pi))
print("check pi*e^-1 =", pi*exp(-1), " pi*e^-8=", pi*exp(-8))
