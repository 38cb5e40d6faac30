"""Free-run simulation: one fixed-step RK4 scheme for every model.

The NumPy engine (freerun), the compiled kernel (kernel) and restarted k-step prediction
(prediction).
"""
