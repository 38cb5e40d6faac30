"""The identified model as self-contained code for a controller: C99, MATLAB or NumPy.

``debist export`` writes the RBF model of Eq. 37 (with its backbone and physics prior) as
plain source files a controller or a Simulink model can build without debist (C99, a MATLAB
function file for a Simulink MATLAB Function block or Octave, or NumPy): the term table
of :meth:`debist.model.rbf.RBFModel.table_model` as constant arrays, the state
derivative, one classical RK4 step with inputs linear between two samples (the scheme of
debist's free run with ``substeps = 1`` and ``interpolation = "linear"``, so the exported
code reproduces :func:`debist.simulate.freerun.simulate` to rounding), and the characteristic
curves restoring force, d(q) and g_i(q) as a lookup table. The generators are pure functions
returning file contents, rendered from the jinja2 templates in ``templates/`` that insert
free text and numbers only through each language's escaping and literal filters (see
:mod:`debist.export.common`); :func:`debist.export.files.load_identified` reads a run's
identified model and checks that the identify stage is up to date, and
:func:`debist.export.files.export_files` gives the files of one format. This package's
``__init__`` imports none of its modules.

References
----------
Masoud & Maas 2025, Eq. 37-40; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1
(classical RK4); ISO/IEC 9899:1999 (C99); MathWorks, "Function Basics" and "MATLAB Function
block" (local functions, fixed-size code generation); NumPy ``numpy.interp`` (the table
semantics).
"""
