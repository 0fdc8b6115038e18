#!/usr/bin/env python3
"""Laine & Karras 2011 on eight stacked full-pixel layers of alpha 0.1 drawn front to back, in one
pixel, independently of the Rust code: Figure 7 with CalcAlphaRef (Figure 4) against Enderton et
al.'s R = floor(alpha m + xi) with the depth test first. docs/reproduction.md, "Figure 3b", quotes
its output: the stratified method is the noisier here, because after the depth test the m samples
left are the first m of a 16-span of references, stratified only when m is a power of two, while
Enderton's integer count is the best possible for any m. Run: python3 xtask/reproduce/lk_stack.py
"""
import random
M=0xFFFFFFFF
C=[0x6C50B47C,0xB82F1E52,0xC7AFE638,0x8D22F6E6]
def rev(x): return int(f"{x:032b}"[::-1],2)
def ref(n,pixel,surface,spp):
    x=(n+pixel*spp)&M; x=(rev(x)+surface)&M
    for c in C: x^=(x*c)&M
    return x/2**32
def lk(spp,a,layers,pixel,rng):
    written=[False]*spp; sid=rng.getrandbits(32)
    covered=False; total=0
    for l in range(layers):
        alive=[s for s in range(spp) if not written[s]]
        if covered: sid=(sid+1)&M
        covered=True
        for n,s in enumerate(alive):
            if a>ref(n,pixel,sid,spp): written[s]=True; total+=1
    return total/spp
def enderton(spp,a,layers,rng):
    m=spp; total=0
    for l in range(layers):
        r=min(int(a*m+rng.random()),m); total+=r; m-=r
    return total/spp
rng=random.Random(1)
for spp in (8,16,32):
    want=1-(1-0.1)**8
    for name,f in (("stratified",lambda p:lk(spp,0.1,8,p,rng)),("enderton",lambda p:enderton(spp,0.1,8,rng))):
        v=[f(p) for p in range(4000)]
        mse=sum((x-want)**2 for x in v)/len(v); bias=sum(v)/len(v)-want
        print(spp,name,"rmse(8-bit)=%.2f bias=%.4f"%(255*mse**0.5,bias))
# The second layer alone: m samples left of 16, counts written by each method.
for m in (14,15,16):
    lkc=[];enc=[]
    for p in range(4000):
        sid=rng.getrandbits(32)
        lkc.append(sum(1 for n in range(m) if 0.1>ref(n,p,sid,16)))
        enc.append(min(int(0.1*m+rng.random()),m))
    var=lambda v:sum((x-sum(v)/len(v))**2 for x in v)/len(v)
    print("m=%d stratified mean %.3f var %.3f | enderton mean %.3f var %.3f"%(m,sum(lkc)/4000,var(lkc),sum(enc)/4000,var(enc)))
