"""The models of Eq. 37-40 (Masoud & Maas 2025).

The RBF basis (Eq. 38-39), the term library, h(v) and the term table every engine evaluates,
the identified RBF model, and the SINDy and NARX peers.
"""
