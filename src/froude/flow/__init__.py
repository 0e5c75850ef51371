"""Orchestration: prepare a clip once, then scale / accelerate / naive; results and their files;
the kinds of locomotion (one type per machine); the speeds a clip reaches, speed goals and changes; what is
in a clip."""
