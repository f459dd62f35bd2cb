"""Training, evaluation and the command line of coopnav (installed as ``coopnav_env.training``)."""

from coopnav_env.old_names import redirect as _redirect_old_name

# imported as 'training' (a source checkout): becomes 'coopnav_env.training'
_redirect_old_name(__name__)
