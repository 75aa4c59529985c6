"""Tests of the training room (agents/training): the trainers, their run directories, selection and shipping."""
