"""Report section 4: neighbourhoods (mesh 1-ring, k-NN, Delaunay), weights, curvature, L(n)
/ L(kappa) / L(f).
"""
