# cylinder-obj.py AX AY AZ BX BY BZ R OUT.obj: an OBJ cylinder from a to b in voxel-index coordinates,
# radius r (voxel units on every axis, so elliptical in world space on anisotropic scans), 32 sides,
# capped: the shape of geometry::Mesh::cylinder (its ring may start at another angle). The needles of the inverse-warp cost figures:
#   python3 benches/scripts/cylinder-obj.py 10 30 20 118 100 95 2 needle-head.obj
#   python3 benches/scripts/cylinder-obj.py 40 100 5 470 400 42 6 needle-chest.obj
import sys, math
ax,ay,az,bx,by,bz,r = map(float, sys.argv[1:8]); out = sys.argv[8]; n = 32
a=(ax,ay,az); b=(bx,by,bz)
w=[b[i]-a[i] for i in range(3)]; L=math.sqrt(sum(x*x for x in w)); w=[x/L for x in w]
h = (1,0,0) if abs(w[0]) < 0.9 else (0,1,0)
u=[h[1]*w[2]-h[2]*w[1], h[2]*w[0]-h[0]*w[2], h[0]*w[1]-h[1]*w[0]]; ul=math.sqrt(sum(x*x for x in u)); u=[x/ul for x in u]
v=[w[1]*u[2]-w[2]*u[1], w[2]*u[0]-w[0]*u[2], w[0]*u[1]-w[1]*u[0]]
V=[a,b]
for e in (a,b):
    for s in range(n):
        ph=2*math.pi*s/n
        V.append(tuple(e[i]+r*(math.cos(ph)*u[i]+math.sin(ph)*v[i]) for i in range(3)))
T=[]
lo=lambda s: 3+2+s%n-2; hi=lambda s: 3+2+n+s%n-2
for s in range(n):
    T += [(1,lo(s+1),lo(s)),(2,hi(s),hi(s+1)),(lo(s),lo(s+1),hi(s+1)),(lo(s),hi(s+1),hi(s))]
with open(out,'w') as f:
    for p in V: f.write("v %g %g %g\n"%p)
    for t in T: f.write("f %d %d %d\n"%t)
