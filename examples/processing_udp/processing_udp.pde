/**
 * optrack's tracks in Processing, from the UDP JSON output (OpenPTrack's format).
 *
 * Needs the "UDP" library by Stephane Cousot (Sketch > Import Library > Add Library,
 * search "UDP"). Each datagram is one JSON document with no trailing NUL byte, so
 * parseJSONObject reads it as it is: a frame of tracks (header.frame_id "world") or
 * the heartbeat every 0.25 s ("heartbeat": alive_IDs, max_ID), and, while the
 * skeleton stage runs (optrack run --skeleton), frames of skeletons ("pose_tracks",
 * OpenPTrack v2's pose message), drawn here as their joints seen from above.
 *
 * optrack sends to 127.0.0.1:21234 by default; for another computer run
 *   optrack run --udp THIS_COMPUTER_IP:21234
 */
import hypermedia.net.*;

final int PORT = 21234;              // OpenPTrack's port
final float PIXELS_PER_METRE = 50;   // 16 m x 12 m around the origin

UDP udp;
JSONArray tracks = new JSONArray();
JSONArray skeletons = new JSONArray();
String alive = "";

void setup() {
  size(800, 600);
  udp = new UDP(this, PORT);
  udp.listen(true);
  textSize(12);
}

void receive(byte[] data, String ip, int port) {
  JSONObject message = parseJSONObject(new String(data));
  if (message == null) return;
  String frame = message.getJSONObject("header").getString("frame_id");
  if (frame.equals("heartbeat")) {
    alive = message.getJSONArray("alive_IDs").toString() + "  max ID " + message.getInt("max_ID");
  } else if (message.hasKey("pose_tracks")) {
    skeletons = message.getJSONArray("pose_tracks");
  } else {
    tracks = message.getJSONArray("tracks");
  }
}

void draw() {
  background(20);
  stroke(60);
  line(width / 2, 0, width / 2, height);   // world axes through the origin
  line(0, height / 2, width, height / 2);
  noStroke();
  JSONArray now = tracks;
  for (int i = 0; i < now.size(); i++) {
    JSONObject t = now.getJSONObject(i);
    float u = width / 2 + t.getFloat("x") * PIXELS_PER_METRE;
    float v = height / 2 - t.getFloat("y") * PIXELS_PER_METRE;   // world y up the screen
    colorMode(HSB, 360, 100, 100);
    fill((t.getInt("id") * 47) % 360, 70, 90);
    ellipse(u, v, 20, 20);
    colorMode(RGB, 255);
    fill(230);
    text("#" + t.getInt("id") + "  " + nf(t.getFloat("height"), 1, 2) + " m", u + 12, v + 4);
  }
  JSONArray bodies = skeletons;
  for (int i = 0; i < bodies.size(); i++) {
    JSONObject s = bodies.getJSONObject(i);
    JSONObject joints = s.getJSONObject("joints");
    for (Object name : joints.keys()) {
      JSONObject j = joints.getJSONObject((String) name);
      fill(255, 255 * j.getFloat("confidence"), 0);
      ellipse(width / 2 + j.getFloat("x") * PIXELS_PER_METRE,
              height / 2 - j.getFloat("y") * PIXELS_PER_METRE, 5, 5);
    }
  }
  fill(200);
  text("alive " + alive, 10, height - 10);
}
