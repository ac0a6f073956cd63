"""Sessions in one place: the record a calibration leaves, the check of a new session, the between-session model.

The data (:class:`~robocal_uncertainty.core.session.SessionState`, ``Verification``,
``ValidatedLevel``...) live in core, where the calibration file reads and writes them; what
computes them lives here, one job per module:

- :mod:`.field`: the model error a calibration leaves (per-pose size, degrees of freedom, the
  field correlated over the configurations);
- :mod:`.cross_validation`: the model error from held-out folds;
- :mod:`.state`: the session record of a point calibration (:func:`~.state.session_state`);
- :mod:`.validated_level`: the calibration's error level on its own held-out poses;
- :mod:`.verification`: re-register a check of a new session and test it
  (:func:`~.verification.verify_session`), with :mod:`.check_campaign`,
  :mod:`.null_distribution`, :mod:`.level` and :mod:`.tracker_move`;
- :mod:`.between`: the between-session component from several sessions.

Import from the modules; this package re-exports nothing, so importing one module does not
load the others (the uncertainty sources import none of them).
"""
