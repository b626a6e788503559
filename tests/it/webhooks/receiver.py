"""A WMS's webhook receiver written as a WMS would, with the Standard Webhooks library for
Python (`standardwebhooks`) and nothing of rackd's: tests/it/webhooks/python.rs runs it.

Usage: python receiver.py SECRET

Serves HTTP on 127.0.0.1 on a free port and prints that port on the first line of stdout.
Every POST is verified with `Webhook(SECRET).verify(body, headers)`, which also checks the
timestamp's tolerance (5 minutes): verified, it prints `verified SEQ TYPE` and answers
204; refused, it prints `rejected REASON` and answers 400. Each line is flushed before the
answer is sent, so once rackd has its answer the line is on stdout.
"""

import sys
from http.server import BaseHTTPRequestHandler, HTTPServer

from standardwebhooks import Webhook, WebhookVerificationError


def handler(webhook):
    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):
            body = self.rfile.read(int(self.headers.get("content-length", "0")))
            try:
                event = webhook.verify(body, dict(self.headers))
            except WebhookVerificationError as e:
                print(f"rejected {e}", flush=True)
                status = 400
            else:
                print(f"verified {event['seq']} {event['type']}", flush=True)
                status = 204
            self.send_response(status)
            self.end_headers()

        def log_message(self, format, *args):
            # The default logs every request to stderr; stdout already tells what matters.
            pass

    return Handler


def main():
    server = HTTPServer(("127.0.0.1", 0), handler(Webhook(sys.argv[1])))
    print(server.server_address[1], flush=True)
    server.serve_forever()


if __name__ == "__main__":
    main()
