"""Node processes for tests: started with their output in a log file, killed if a test leaves
them behind."""

import subprocess

import pytest


@pytest.fixture
def start(tmp_path):
    """Starts a command with its output in a log file; kills what is left at the end."""
    processes = []

    def start(*command: str) -> subprocess.Popen:
        log_path = tmp_path / f"process-{len(processes)}.log"
        with open(log_path, "w") as log:
            process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
        process.log_path = log_path
        processes.append(process)
        return process

    yield start
    for process in processes:
        if process.poll() is None:
            process.kill()
            process.wait()


def log(process: subprocess.Popen) -> str:
    return process.log_path.read_text()
