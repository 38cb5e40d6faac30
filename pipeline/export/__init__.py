"""The identified model as self-contained code for a controller: C99, MATLAB or NumPy.

``debist export`` writes the RBF model of Eq. 37 (with its backbone and physics prior) as
plain source files a controller or a Simulink model can build without debist (C99, MATLAB
function files for a Simulink MATLAB Function block or Octave, or NumPy): the term table
of :meth:`debist.model.rbf.RBFModel.table_model` as constant arrays, the state derivative,
and the integration scheme the run's validate stage scored (:mod:`debist.export.scheme`:
``ns`` RK4 sub-steps per sample and its input interpolation, read from the run with the
functions validate uses). Two entries integrate: the whole-record free run (the record's
inputs interpolated as validate does, band-limited through the polyphase FIR taps of
``scipy.signal.resample_poly`` embedded as a table, or linearly; validate's initial state,
divergence bound and slip projection), which reproduces validate's free run and its
NRMSE(q); and the causal per-sample step (the same ``ns`` sub-steps, inputs linear between
two samples), a controller's step, which is not the scored scheme when validate
interpolates band-limited. Each file's header states the scheme and, per record of the run,
the NRMSE(q) both entries achieve, computed at export by debist's simulator. The
characteristic curves restoring force, d(q) and g_i(q) come as a lookup table. The
generators are pure functions returning file contents, rendered from the jinja2 templates in
``templates/`` that insert free text and numbers only through each language's escaping and
literal filters (see :mod:`debist.export.common`); :func:`debist.export.files.load_identified`
reads a run's identified model and checks that the identify stage is up to date,
:func:`debist.export.files.load_scheme` computes the scheme on the run's records, and
:func:`debist.export.files.export_files` gives the files of one format. This package's
``__init__`` imports none of its modules.

References
----------
Masoud & Maas 2025, Eq. 37-40; Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1
(classical RK4); SciPy ``scipy.signal.resample_poly`` (the band-limited interpolation);
ISO/IEC 9899:1999 (C99); MathWorks, "Function Basics" and "MATLAB Function
block" (local functions, fixed-size code generation); NumPy ``numpy.interp`` (the table
semantics).
"""
