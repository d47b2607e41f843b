"""The studies: each makes tables of the README and docs/ from its own flights (``run_stack.py study --list``).

One module per study, beside ``campaign/``: its one-line docstring says which table it makes and which doc holds
it; ``add_arguments(parser)`` declares its options and ``run(args)`` flies (campaigns through
``flight_stack.campaign``, single flights through ``flight_stack.api.fly`` or the embedded backend) and writes
the markdown table into ``--out DIR``. ``common`` holds what they share; ``cli`` is the ``study`` command.
"""
