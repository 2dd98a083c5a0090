"""A cluster that is not there (issue 24, part 5): ``--scheduler`` is checked before any
connection, reached within a time limit, and every failure is one line naming the address.
The time limit is what ends the slow cases; the tests assert on the message only."""

import http.server
import socket
import sys
import threading
from pathlib import Path

import pytest

from cassi_fit import cli, synth
from cassi_fit.corpus import (
    DEFAULT_TIMEOUT_S,
    SchedulerError,
    check_scheduler,
    connect_scheduler,
    parse_scheduler_address,
    scheduler_timeout,
)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.JAW_WAGGING_TASK])


@pytest.fixture
def http_server():
    """A web server (as a Dask dashboard is): it waits for a request and says nothing."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0),
                                             http.server.SimpleHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.fixture
def closed_port():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"127.0.0.1:{sock.getsockname()[1]}"  # nothing listens once it is closed


def _cassi(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    return code, capsys.readouterr().err


def test_a_web_server_is_one_line_naming_the_address(dataset, http_server, tmp_path, capsys):
    code, err = _cassi(capsys, "jaw", dataset, "--out", tmp_path / "o", "--scheduler",
                       http_server, "--scheduler-timeout", "2", "--quiet")
    assert code == 2
    assert err.count("\n") == 1 and err.startswith(f"cassi: error: {http_server}: ")
    assert "no Dask handshake within 2 s" in err and "dashboard" in err
    assert not (tmp_path / "o").exists()


def test_a_closed_port_is_one_line_naming_the_address(dataset, closed_port, tmp_path, capsys):
    code, err = _cassi(capsys, "evaluate", dataset, "--out", tmp_path / "o", "--scheduler",
                       closed_port, "--quiet")
    assert code == 2
    assert err == (f"cassi: error: tcp://{closed_port}: cannot connect (Connection "
                   "refused); is a Dask scheduler running there?\n")


def test_a_server_speaking_another_protocol_is_not_read_as_dask():
    """Eight bytes of text read as a Dask message length asked for exabytes before."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def greet():
        conn, _ = server.accept()
        with conn:
            conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
            try:
                conn.recv(1)  # until the client leaves
            except OSError:
                pass

    thread = threading.Thread(target=greet, daemon=True)
    thread.start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    with pytest.raises(SchedulerError, match="answered 'SSH-2.0-'..., not a Dask handshake"):
        check_scheduler(address, timeout=10)
    thread.join()
    server.close()


@pytest.mark.parametrize(("address", "message"), [
    ("http://host:8786", "not a Dask scheduler address (scheme 'http'"),
    ("tcp://:8786", "no host in the scheduler address"),
    ("tcp://host:0", "the port must be a number in 1..65535, got '0'"),
    ("tcp://host:dask", "the port must be a number in 1..65535, got 'dask'"),
    ("", "empty address"),
])
def test_malformed_addresses_are_refused_before_any_connection(address, message):
    with pytest.raises(SchedulerError, match=message.replace("(", r"\(").replace(".", r"\.")):
        parse_scheduler_address(address)


def test_addresses_and_the_time_limit(monkeypatch):
    assert str(parse_scheduler_address("host")) == "tcp://host:8786"
    assert str(parse_scheduler_address("TLS://10.0.0.1:9000/")) == "tls://10.0.0.1:9000"
    assert str(parse_scheduler_address("tcp://[::1]:8786")) == "tcp://[::1]:8786"
    monkeypatch.delenv("CASSI_SCHEDULER_TIMEOUT", raising=False)
    assert scheduler_timeout() == DEFAULT_TIMEOUT_S
    monkeypatch.setenv("CASSI_SCHEDULER_TIMEOUT", "2.5")
    assert scheduler_timeout() == 2.5 and scheduler_timeout(7) == 7
    monkeypatch.setenv("CASSI_SCHEDULER_TIMEOUT", "soon")
    with pytest.raises(Exception, match="CASSI_SCHEDULER_TIMEOUT must be a positive number"):
        scheduler_timeout()


def test_without_the_corpus_extra_it_says_which_to_install(monkeypatch, dataset, tmp_path,
                                                           capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(Exception, match=r"install the 'corpus' extra"):
        connect_scheduler("tcp://127.0.0.1:8786")
    code, err = _cassi(capsys, "jaw", dataset, "--out", tmp_path / "o", "--scheduler",
                       "tcp://127.0.0.1:8786", "--quiet")
    assert code == 2 and "pip install 'cassi_fit[corpus]'" in err
    assert "ModuleNotFoundError" not in err


def test_a_bad_address_fails_before_the_dataset_is_read(tmp_path, capsys):
    missing = Path(tmp_path / "no-such-dataset")
    missing.mkdir()
    code, err = _cassi(capsys, "jaw", missing, "--out", tmp_path / "o", "--scheduler",
                       "http://x:1")
    assert code == 2 and "scheme 'http'" in err
