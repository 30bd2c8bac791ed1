"""An iterated EKF from quadest's parts: a Taylor linearisation, re-done at each iterate."""

from dataclasses import dataclass

from quadest.estimators.gaussian_filter import GaussianFilter
from quadest.estimators.integrations import AffineModel, Integration


@dataclass(frozen=True)
class MyTaylor:
    """g(x) ≈ g(m) + J (x − m) + e, e ~ N(0, noise): the EKF's linearisation."""

    name: str = "my_taylor"

    def transition(self, model, m, P, u, factor):
        return AffineModel(model.f(m[:, None], u)[:, 0], model.F(m, u), model.Q)

    def measurement(self, model, sensor, m, P, u, factor):
        meas = model.measurement(sensor)
        return AffineModel(meas.h(m[:, None], u)[:, 0], model.measurement_jacobian(sensor, m, u), meas.R)


@dataclass
class MyIEKFParams:
    kind: str = "my_iekf"
    iterations: int = 10


class MyIEKF(GaussianFilter):
    """Gauss–Newton on each measurement update (Bell & Cathey 1993)."""

    config_name = "my_iekf"
    Params = MyIEKFParams

    def __init__(self, model, iterations: int = 10) -> None:
        super().__init__(model, Integration(MyTaylor(), iterations))
