"""Evaluation: CLEAR MOT scores, replays of detection streams, synthetic scenes, benchmarks."""
