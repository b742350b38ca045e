"""Stand-ins at true hardware boundaries, each checked against the real thing's documented behaviour.

Nothing in the product imports this package unless a config asks for it explicitly
(``[arm.xarm] sdk = "fake"``); the tests and the fault-injection daemon use it directly.
"""
