"""The shared quadrotor: OS4 rigid body with rotors and motors, backstepping controller,
scenarios, the truth simulation that flies them, and the plant the closed loop steps
(docs/sources.md, "The quadrotor model")."""
