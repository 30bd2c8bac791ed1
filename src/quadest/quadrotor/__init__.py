"""The shared quadrotor: OS4 rigid body with rotors and motors, backstepping controller,
scenarios, and the truth simulation that flies them (``../shared/reference/quadrotor.md``)."""
